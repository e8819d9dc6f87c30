// A foot pedal or joystick as the drill's controls: an axis sets the drill's speed, buttons act as
// clutch and tool switch. The mapping is a small JSON file (docs/devices.md), read once; the logic
// here takes the axes and buttons as numbers, so it runs without GLFW (the window polls GLFW's
// joystick API and hands the values in).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace trephine {

inline constexpr int kPedalMaxIndex = 63; // axes and buttons a mapping may name (0-63)

struct PedalMap {
    std::string joystick; // part of the joystick's name (any case); "": the first one attached
    // The speed axis (nullopt: none) and its raw values at rest and fully down (GLFW: -1..1); a
    // pedal pressed less than deadZone of its travel does not drill.
    std::optional<int> speedAxis = 0;
    float released = -1.0f, pressed = 1.0f;
    float deadZone = 0.05f;
    std::optional<int> clutchButton = 0; // held: the tool stays put while the hand moves
    std::optional<int> toolButton = 1;   // pressed: the next tool
};

// Reads a mapping (keys left out keep PedalMap's defaults); throws Error in one line naming the
// file, the key and what was wrong. "default" is the built-in mapping.
PedalMap readPedalMap(const std::string& path);
PedalMap parsePedalMap(const std::string& text, const std::string& source);
// The mapping as JSON (the defaults, for `trephine devices` and the docs).
std::string pedalMapJson(const PedalMap& map);

// One joystick's state as polled.
struct JoystickInput {
    std::string name;
    std::vector<float> axes;
    std::vector<uint8_t> buttons; // 1: pressed
};

// Which of the attached joysticks the mapping takes (-1: none matches).
int chooseJoystick(const PedalMap& map, const std::vector<JoystickInput>& attached);

struct PedalOutput {
    bool present = false;       // the mapped joystick is attached and has the mapped controls
    std::optional<float> speed; // 0-1 (nullopt: no speed axis mapped or none attached)
    bool clutch = false;
    bool toolSwitch = false; // the tool button went down since the last update
};

// The mapping applied to successive polls (it remembers the tool button, to count presses).
class PedalControl {
public:
    explicit PedalControl(PedalMap map) : m_map(std::move(map)) {}
    PedalOutput update(const std::vector<JoystickInput>& attached);
    const PedalMap& map() const { return m_map; }

private:
    PedalMap m_map;
    bool m_toolWas = false;
};

// The drill's speed (0-1) for a raw axis value under `map`.
float pedalSpeed(const PedalMap& map, float raw);

} // namespace trephine
