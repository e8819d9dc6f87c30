// The pedal and joystick mapping: the file is read (keys left out keep their defaults), bad files
// are refused in one line naming the key, and the mapping applied to polled axes and buttons (a
// fake joystick: GLFW has none under Xvfb) sets the speed, holds the clutch and counts presses.
#include "libsim_devices/pedal.h"

#include "libsim/error.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>

using namespace trephine;

namespace {

std::string refusal(const std::string& text) {
    try {
        parsePedalMap(text, "p.json");
    } catch (const Error& e) {
        return e.what();
    }
    return "accepted";
}

JoystickInput pedal(float axis, bool b0 = false, bool b1 = false) {
    return {"Acme USB Foot Pedal", {axis}, {uint8_t(b0), uint8_t(b1)}};
}

} // namespace

TEST(PedalMap, TheDefaultMappingAndAFileThatChangesSomeKeys) {
    const PedalMap d = readPedalMap("default");
    EXPECT_EQ(d.speedAxis, 0);
    EXPECT_EQ(d.clutchButton, 0);
    EXPECT_EQ(d.toolButton, 1);
    EXPECT_EQ(d.joystick, "");

    const auto path = std::filesystem::temp_directory_path() / "trephine_pedal_map_test.json";
    std::ofstream(path) << R"({"joystick": "pedal",
        "speed": {"axis": 2, "released": 1.0, "pressed": -1.0, "dead_zone": 0.1},
        "clutch": null, "tool_switch": {"button": 4}})";
    const PedalMap m = readPedalMap(path.string());
    std::filesystem::remove(path);
    EXPECT_EQ(m.joystick, "pedal");
    EXPECT_EQ(m.speedAxis, 2);
    EXPECT_FLOAT_EQ(m.released, 1.0f);
    EXPECT_FLOAT_EQ(m.pressed, -1.0f);
    EXPECT_FLOAT_EQ(m.deadZone, 0.1f);
    EXPECT_FALSE(m.clutchButton);
    EXPECT_EQ(m.toolButton, 4);
    // What the docs show round-trips.
    const PedalMap back = parsePedalMap(pedalMapJson(m), "json");
    EXPECT_EQ(back.speedAxis, m.speedAxis);
    EXPECT_EQ(back.toolButton, m.toolButton);
    EXPECT_FALSE(back.clutchButton);
}

TEST(PedalMap, BadMappingsAreRefusedInOneLineNamingTheKey) {
    struct Case {
        const char* text;
        const char* says;
    };
    const Case cases[] = {
        {"{", "not JSON"},
        {"[1, 2]", "must be a JSON object"},
        {R"({"sped": {"axis": 0}})", "sped: unknown key"},
        {R"({"speed": {"axis": -1}})", "speed.axis: must be a whole number 0-63"},
        {R"({"speed": {"axis": 1.5}})", "speed.axis"},
        {R"({"speed": {"axis": "left"}})", "speed.axis"},
        {R"({"speed": {"axiz": 0}})", "speed.axiz: unknown key"},
        {R"({"speed": {"pressed": 2}})", "speed.pressed: must be a number from -1"},
        {R"({"speed": {"released": 0.5, "pressed": 0.55}})", "speed.pressed: must differ"},
        {R"({"speed": {"dead_zone": 0.95}})", "speed.dead_zone"},
        {R"({"speed": 3})", "speed: must be an object or null"},
        {R"({"clutch": {}})", "clutch.button: missing"},
        {R"({"clutch": {"button": 2}, "tool_switch": {"button": 2}})",
         "tool_switch.button: is the clutch's button too"},
        {R"({"joystick": 7})", "joystick: must be a string"},
        {R"({"speed": null, "clutch": null, "tool_switch": null})", "maps nothing"},
    };
    for (const Case& c : cases) {
        const std::string why = refusal(c.text);
        EXPECT_NE(why.find(c.says), std::string::npos) << c.text << " -> " << why;
        EXPECT_EQ(why.rfind("pedal map p.json: ", 0), 0u) << why;
        EXPECT_EQ(why.find('\n'), std::string::npos) << why;
    }
    try {
        readPedalMap("/no/such/pedal.json");
        FAIL();
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/no/such/pedal.json: cannot read"),
                  std::string::npos);
    }
}

TEST(PedalMap, TheAxisSetsTheSpeedFromTheDeadZonesEdge) {
    PedalMap m; // released -1, pressed 1, dead zone 5 %
    EXPECT_EQ(pedalSpeed(m, -1.0f), 0.0f);
    EXPECT_EQ(pedalSpeed(m, -0.92f), 0.0f); // 4 % of the travel: inside the dead zone
    EXPECT_NEAR(pedalSpeed(m, 0.0f), (0.5f - 0.05f) / 0.95f, 1e-6f);
    EXPECT_EQ(pedalSpeed(m, 1.0f), 1.0f);
    EXPECT_EQ(pedalSpeed(m, 7.0f), 1.0f); // beyond the travel: clamped
    EXPECT_EQ(pedalSpeed(m, std::nanf("")), 0.0f);
    m.released = 1.0f; // an inverted pedal
    m.pressed = -1.0f;
    EXPECT_EQ(pedalSpeed(m, -1.0f), 1.0f);
    EXPECT_EQ(pedalSpeed(m, 1.0f), 0.0f);
}

TEST(PedalMap, PolledButtonsHoldTheClutchAndCountToolPresses) {
    PedalControl c{PedalMap{}};
    PedalOutput o = c.update({pedal(1.0f)});
    EXPECT_TRUE(o.present);
    ASSERT_TRUE(o.speed);
    EXPECT_EQ(*o.speed, 1.0f);
    EXPECT_FALSE(o.clutch);
    EXPECT_TRUE(c.update({pedal(-1.0f, true)}).clutch);
    EXPECT_TRUE(c.update({pedal(-1.0f, false, true)}).toolSwitch);
    EXPECT_FALSE(c.update({pedal(-1.0f, false, true)}).toolSwitch) << "held: one press";
    c.update({pedal(-1.0f)});
    EXPECT_TRUE(c.update({pedal(-1.0f, false, true)}).toolSwitch);
    // Unplugged: nothing present, no speed, no clutch.
    o = c.update({});
    EXPECT_FALSE(o.present);
    EXPECT_FALSE(o.speed);
    EXPECT_FALSE(o.clutch);
}

TEST(PedalMap, TheJoystickIsChosenByPartOfItsName) {
    PedalMap m;
    m.joystick = "PEDAL";
    const std::vector<JoystickInput> attached = {{"Xbox Controller", {0.3f, 1.0f}, {1, 1}},
                                                 pedal(-1.0f)};
    EXPECT_EQ(chooseJoystick(m, attached), 1);
    PedalControl c(m);
    PedalOutput o = c.update(attached);
    ASSERT_TRUE(o.speed);
    EXPECT_EQ(*o.speed, 0.0f) << "the pedal's axis, not the gamepad's";
    EXPECT_FALSE(o.clutch);
    m.joystick = "wheel";
    EXPECT_EQ(chooseJoystick(m, attached), -1);
    // A joystick without the mapped axis is not taken as present.
    PedalMap far;
    far.speedAxis = 5;
    EXPECT_FALSE(PedalControl(far).update({pedal(1.0f)}).present);
}
