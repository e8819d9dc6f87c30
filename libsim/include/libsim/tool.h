// Cutting tools: spherical burrs and the cranial perforator. A tool is a cutter shape on a shaft
// with a pose; drilling and haptics query the shape in the tool's local frame.
#pragma once

#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>
#include <string>

namespace trephine {

enum class ToolKind : uint8_t { Burr = 0, Perforator = 1 };

// Sizes a factory accepts (mm). The perforator's proportions follow a 14 mm adult perforator and
// scale with its diameter: a blunt conical tip 4 mm long under a 12 mm cutting cylinder.
inline constexpr float kBurrMinDiameterMm = 1.0f;
inline constexpr float kBurrMaxDiameterMm = 6.0f;
inline constexpr float kPerforatorDiameterMm = 14.0f;
inline constexpr float kPerforatorMinDiameterMm = 6.0f;
inline constexpr float kPerforatorMaxDiameterMm = 16.0f;
inline constexpr float kPerforatorTipLengthMm = 4.0f; // at 14 mm diameter
inline constexpr float kPerforatorCutLengthMm = 12.0f;

// Tool-local frame: the cutter's reference point is the origin and the shaft runs along +z (away
// from the bone when drilling straight down). For a burr the origin is the sphere's centre; for the
// perforator it is the apex of the conical tip.
struct ToolShape {
    ToolKind kind = ToolKind::Burr;
    float diameterMm = 4.0f;  // burr: sphere diameter (1-6 mm); perforator: cylinder diameter
    float tipLengthMm = 0.0f; // perforator: length of the conical tip along the axis
    float cutLengthMm = 0.0f; // perforator: cutting length of the cylinder above the tip

    // Factories: throw Error for a diameter out of range (burr 1-6 mm, perforator 6-16 mm).
    static ToolShape burr(float diameterMm);
    static ToolShape perforator(float diameterMm = kPerforatorDiameterMm);
    // Throws Error when the shape is not one the factories make (e.g. read from a message).
    void validate() const;

    // Signed distance (mm) from a tool-local point to the cutter surface: negative inside. Exact
    // for both shapes (the perforator's is the 2D distance in its meridian plane).
    float signedDistance(glm::vec3 local) const;
    bool contains(glm::vec3 local) const { return signedDistance(local) <= 0.0f; }
    // Radius of a sphere about the origin that holds the whole cutter.
    float boundingRadius() const;
    std::string describe() const; // e.g. "burr 4 mm", "perforator 14 mm"
};

struct ToolPose {
    glm::vec3 position{0.0f};                      // cutter reference point, object space (mm)
    glm::quat orientation{1.0f, 0.0f, 0.0f, 0.0f}; // tool-local to object space

    // The pose whose shaft (+z local) points along shaftAxis (need not be unit length), e.g. the
    // outward surface normal to drill straight in; the roll about the axis is the shortest arc.
    static ToolPose fromAxis(glm::vec3 position, glm::vec3 shaftAxis);

    glm::vec3 toLocal(glm::vec3 p) const { return glm::inverse(orientation) * (p - position); }
    glm::vec3 toObject(glm::vec3 local) const { return orientation * local + position; }
    glm::vec3 axis() const { return orientation * glm::vec3(0, 0, 1); } // shaft direction
};

} // namespace trephine
