// Cutting tools: spherical burrs and the cranial perforator. A tool is a cutter shape on a shaft
// with a pose; drilling and haptics query the shape in the tool's local frame.
#pragma once

#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>
#include <string>

namespace trephine {

enum class ToolKind : uint8_t { Burr = 0, Perforator = 1 };

// Tool-local frame: the cutter's reference point is the origin and the shaft runs along +z (away
// from the bone when drilling straight down). For a burr the origin is the sphere's centre; for the
// perforator it is the apex of the conical tip.
struct ToolShape {
    ToolKind kind = ToolKind::Burr;
    float diameterMm = 4.0f; // burr: sphere diameter (1-6 mm); perforator: cylinder diameter
    float tipLengthMm = 0.0f; // perforator: length of the conical tip along the axis
    float cutLengthMm = 0.0f; // perforator: cutting length of the cylinder above the tip

    static ToolShape burr(float diameterMm);
    static ToolShape perforator(float diameterMm = 14.0f);

    // Signed distance (mm) from a tool-local point to the cutter surface: negative inside.
    float signedDistance(glm::vec3 local) const;
    bool contains(glm::vec3 local) const { return signedDistance(local) <= 0.0f; }
    // Radius of a sphere about the origin that holds the whole cutter.
    float boundingRadius() const;
    std::string describe() const; // e.g. "burr 4 mm", "perforator 14 mm"
};

struct ToolPose {
    glm::vec3 position{0.0f};                     // cutter reference point, object space (mm)
    glm::quat orientation{1.0f, 0.0f, 0.0f, 0.0f}; // tool-local to object space

    glm::vec3 toLocal(glm::vec3 p) const { return glm::inverse(orientation) * (p - position); }
    glm::vec3 toObject(glm::vec3 local) const { return orientation * local + position; }
    glm::vec3 axis() const { return orientation * glm::vec3(0, 0, 1); } // shaft direction
};

} // namespace trephine
