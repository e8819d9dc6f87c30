// The colours the server gives participants (Participants' colour): one palette, so every window
// draws the same person in the same colour.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace trephine::net {

struct Rgb8 {
    uint8_t r = 0, g = 0, b = 0;
    bool operator==(const Rgb8&) const = default;
};

// The palette: distinct on the window's dark grey, none near the marks' yellow.
std::span<const Rgb8> participantPalette();

// The palette index for a newcomer, given the indices the others in the session wear: the first
// nobody wears, else the one fewest wear (the lowest of those).
uint8_t pickParticipantColour(const std::vector<uint8_t>& inUse);

} // namespace trephine::net
