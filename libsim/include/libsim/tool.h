// Cutting tools: a cutter shape on a shaft with a pose; drilling and haptics query the shape in
// the tool's local frame. What each kind of tool is (its cutter, sizes, cutting rule) is in the
// catalogue (libsim/tool_catalogue.h).
#pragma once

#include <cstdint>
#include <glm/gtc/quaternion.hpp>
#include <glm/vec3.hpp>
#include <string>

namespace trephine {

// The catalogue's ids (libsim/tool_catalogue.h), which the wire and session logs carry.
enum class ToolKind : uint8_t { Burr = 0, Perforator = 1, DiamondBurr = 2 };

// Tool-local frame: the cutter's reference point is the origin and the shaft runs along +z (away
// from the bone when drilling straight down). For a sphere the origin is its centre; for a tipped
// cylinder (the perforator) it is the apex of the conical tip.
struct ToolShape {
    ToolKind kind = ToolKind::Burr;
    float diameterMm = 4.0f;  // the sphere's, or the cylinder's
    float tipLengthMm = 0.0f; // tipped cylinder: length of the conical tip along the axis
    float cutLengthMm = 0.0f; // tipped cylinder: cutting length of the cylinder above the tip

    // The tool of `kind` at `diameterMm`: throws Error for a kind not in the catalogue or a
    // diameter out of the kind's range.
    static ToolShape of(ToolKind kind, float diameterMm);
    static ToolShape burr(float diameterMm) { return of(ToolKind::Burr, diameterMm); }
    static ToolShape perforator(float diameterMm);
    static ToolShape perforator(); // at its default diameter (14 mm)
    // Throws Error when the shape is not one the factories make (e.g. read from a message).
    void validate() const;
    bool sphere() const; // a sphere about the origin (else a tipped cylinder)

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
