#include "ui/mesh.h"

#include "libsim/tool_catalogue.h"

#include <cmath>
#include <glm/geometric.hpp>
#include <glm/gtc/constants.hpp>

namespace trephine::ui {

namespace {
constexpr glm::vec4 kSteel{0.72f, 0.74f, 0.78f, 1.0f};
constexpr glm::vec4 kOwner{0.0f, 0.0f, 0.0f, 0.0f}; // alpha 0: the owner's colour
} // namespace

MeshData makeToolMesh(const ToolShape& shape) {
    MeshData m;
    const float r = shape.diameterMm * 0.5f;
    const glm::vec4 head(toolType(shape.kind).colour, 1.0f);
    float top; // where the shaft meets the handpiece's nose
    if (!shape.sphere()) {
        const float tip = shape.tipLengthMm, cut = shape.cutLengthMm;
        m.addLathe({{0.0f, 0.0f}, {r * 0.35f, tip * 0.4f}, {r, tip}}, head);
        m.addLathe({{r, tip}, {r, tip + cut}, {2.5f, tip + cut + 2.0f}}, kSteel);
        m.addLathe({{2.5f, tip + cut + 2.0f}, {2.5f, tip + cut + 14.0f}}, kSteel);
        top = tip + cut + 14.0f;
    } else {
        m.addSphere({0, 0, 0}, r, head);
        const float shaft = std::min(0.8f, r * 0.6f);
        m.addLathe({{shaft, 0.0f}, {shaft, 26.0f}}, kSteel);
        top = 26.0f;
    }
    // Handpiece: a tapered steel nose, then the owner-coloured body with a grip ring and a cap.
    m.addLathe({{0.8f, top}, {3.2f, top + 6.0f}, {5.2f, top + 12.0f}}, kSteel);
    m.addLathe({{5.2f, top + 12.0f}, {6.4f, top + 20.0f}, {6.4f, top + 50.0f}}, kOwner);
    m.addLathe({{6.4f, top + 50.0f}, {6.9f, top + 52.0f}, {6.9f, top + 62.0f}, {6.4f, top + 64.0f}},
               {0.2f, 0.2f, 0.22f, 1.0f});
    m.addLathe(
        {{6.4f, top + 64.0f}, {6.4f, top + 100.0f}, {4.0f, top + 106.0f}, {0.0f, top + 107.0f}},
        kOwner);
    return m;
}

} // namespace trephine::ui
