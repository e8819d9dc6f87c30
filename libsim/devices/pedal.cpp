#include "libsim_devices/pedal.h"

#include "libsim/error.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

namespace trephine {

namespace {

using nlohmann::json;

// One line naming the file and the key.
[[noreturn]] void refuse(const std::string& source, const std::string& key,
                         const std::string& what) {
    throw Error("pedal map " + source + ": " + key + ": " + what);
}

void onlyKeys(const json& j, const std::string& source, const std::string& where,
              std::initializer_list<const char*> known) {
    for (const auto& [k, v] : j.items()) {
        if (std::find_if(known.begin(), known.end(), [&k](const char* n) { return k == n; }) ==
            known.end()) {
            std::string list;
            for (const char* n : known)
                list += (list.empty() ? "" : ", ") + std::string(n);
            refuse(source, where.empty() ? k : where + "." + k,
                   "unknown key (known: " + list + ")");
        }
    }
}

std::optional<int> index(const json& j, const std::string& source, const std::string& key) {
    if (j.is_null())
        return std::nullopt;
    if (!j.is_number_integer() || j.get<int64_t>() < 0 || j.get<int64_t>() > kPedalMaxIndex)
        refuse(source, key,
               "must be a whole number 0-" + std::to_string(kPedalMaxIndex) + " or null, not " +
                   j.dump());
    return int(j.get<int64_t>());
}

float number(const json& j, const std::string& source, const std::string& key, float lo, float hi) {
    if (!j.is_number() || !std::isfinite(j.get<double>()) || j.get<double>() < lo ||
        j.get<double>() > hi)
        refuse(source, key,
               "must be a number from " + json(lo).dump() + " to " + json(hi).dump() + ", not " +
                   j.dump());
    return j.get<float>();
}

// A control's object ({"button": N} or {"axis": N, ...}) or null (the control is not used).
const json* object(const json& root, const char* key, const std::string& source) {
    if (!root.contains(key))
        return nullptr;
    const json& j = root.at(key);
    if (!j.is_null() && !j.is_object())
        refuse(source, key, "must be an object or null, not " + j.dump());
    return &j;
}

void readButton(const json& root, const char* key, const std::string& source,
                std::optional<int>& out) {
    if (const json* j = object(root, key, source)) {
        if (j->is_null()) {
            out.reset();
            return;
        }
        onlyKeys(*j, source, key, {"button"});
        if (!j->contains("button"))
            refuse(source, std::string(key) + ".button",
                   "missing (or make " + std::string(key) + " null)");
        out = index(j->at("button"), source, std::string(key) + ".button");
    }
}

void readSpeed(const json& root, const std::string& source, PedalMap& m) {
    const json* j = object(root, "speed", source);
    if (!j)
        return;
    if (j->is_null()) {
        m.speedAxis.reset();
        return;
    }
    onlyKeys(*j, source, "speed", {"axis", "released", "pressed", "dead_zone"});
    if (j->contains("axis"))
        m.speedAxis = index(j->at("axis"), source, "speed.axis");
    if (j->contains("released"))
        m.released = number(j->at("released"), source, "speed.released", -1.0f, 1.0f);
    if (j->contains("pressed"))
        m.pressed = number(j->at("pressed"), source, "speed.pressed", -1.0f, 1.0f);
    if (j->contains("dead_zone"))
        m.deadZone = number(j->at("dead_zone"), source, "speed.dead_zone", 0.0f, 0.9f);
    if (std::abs(m.pressed - m.released) < 0.1f)
        refuse(source, "speed.pressed",
               "must differ from speed.released by at least 0.1 (the pedal's travel)");
}

std::string lower(std::string s) {
    for (char& c : s)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

} // namespace

PedalMap parsePedalMap(const std::string& text, const std::string& source) {
    json root;
    try {
        root = json::parse(text);
    } catch (const json::parse_error& e) {
        // nlohmann's message names the byte; keep it on one line.
        std::string what = e.what();
        std::replace(what.begin(), what.end(), '\n', ' ');
        throw Error("pedal map " + source + ": not JSON (" + what + ")");
    }
    if (!root.is_object())
        throw Error("pedal map " + source + ": must be a JSON object, not " + root.type_name());
    onlyKeys(root, source, "", {"joystick", "speed", "clutch", "tool_switch"});
    PedalMap m;
    if (root.contains("joystick")) {
        if (!root["joystick"].is_string())
            refuse(source, "joystick",
                   "must be a string (part of the joystick's name), not " +
                       root["joystick"].dump());
        m.joystick = root["joystick"].get<std::string>();
    }
    readSpeed(root, source, m);
    readButton(root, "clutch", source, m.clutchButton);
    readButton(root, "tool_switch", source, m.toolButton);
    if (m.clutchButton && m.toolButton && *m.clutchButton == *m.toolButton)
        refuse(source, "tool_switch.button",
               "is the clutch's button too (" + std::to_string(*m.clutchButton) +
                   "): give each its own");
    if (!m.speedAxis && !m.clutchButton && !m.toolButton)
        throw Error("pedal map " + source + ": maps nothing (speed, clutch and tool_switch are " +
                    "all null)");
    return m;
}

PedalMap readPedalMap(const std::string& path) {
    if (path == "default")
        return PedalMap{};
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw Error("pedal map " + path + ": cannot read it (no such file, or no permission)");
    std::ostringstream text;
    text << in.rdbuf();
    if (text.str().size() > 64 * 1024)
        throw Error("pedal map " + path + ": over 64 KiB; a mapping is a few lines");
    return parsePedalMap(text.str(), path);
}

std::string pedalMapJson(const PedalMap& m) {
    json j;
    j["joystick"] = m.joystick;
    // As read (floats printed as the short decimals a person wrote, not 0.05000000074505806).
    auto dec = [](float v) { return std::round(double(v) * 1e4) / 1e4; };
    j["speed"] = m.speedAxis ? json{{"axis", *m.speedAxis},
                                    {"released", dec(m.released)},
                                    {"pressed", dec(m.pressed)},
                                    {"dead_zone", dec(m.deadZone)}}
                             : json(nullptr);
    j["clutch"] = m.clutchButton ? json{{"button", *m.clutchButton}} : json(nullptr);
    j["tool_switch"] = m.toolButton ? json{{"button", *m.toolButton}} : json(nullptr);
    return j.dump();
}

int chooseJoystick(const PedalMap& map, const std::vector<JoystickInput>& attached) {
    const std::string want = lower(map.joystick);
    for (size_t i = 0; i < attached.size(); ++i)
        if (want.empty() || lower(attached[i].name).find(want) != std::string::npos)
            return int(i);
    return -1;
}

float pedalSpeed(const PedalMap& map, float raw) {
    if (!std::isfinite(raw))
        return 0.0f;
    const float u = std::clamp((raw - map.released) / (map.pressed - map.released), 0.0f, 1.0f);
    // From the dead zone's edge, so the drill starts slowly rather than jumping.
    return u <= map.deadZone ? 0.0f : (u - map.deadZone) / (1.0f - map.deadZone);
}

PedalOutput PedalControl::update(const std::vector<JoystickInput>& attached) {
    PedalOutput out;
    const int i = chooseJoystick(m_map, attached);
    if (i < 0) {
        m_toolWas = false;
        return out;
    }
    const JoystickInput& js = attached[size_t(i)];
    auto button = [&js](std::optional<int> b) {
        return b && size_t(*b) < js.buttons.size() && js.buttons[size_t(*b)] != 0;
    };
    out.present = true;
    if (m_map.speedAxis) {
        if (size_t(*m_map.speedAxis) < js.axes.size())
            out.speed = pedalSpeed(m_map, js.axes[size_t(*m_map.speedAxis)]);
        else
            out.present = false; // this joystick lacks the mapped axis
    }
    out.clutch = button(m_map.clutchButton);
    const bool tool = button(m_map.toolButton);
    out.toolSwitch = tool && !m_toolWas;
    m_toolWas = tool;
    return out;
}

} // namespace trephine
