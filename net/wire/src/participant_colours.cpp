#include "net/participant_colours.h"

#include <algorithm>
#include <array>

namespace trephine::net {

namespace {
constexpr Rgb8 kPalette[] = {
    {51, 115, 217},  // blue
    {217, 89, 51},   // red-orange
    {77, 179, 77},   // green
    {191, 77, 191},  // magenta
    {64, 191, 204},  // cyan
    {242, 140, 179}, // pink
    {150, 130, 240}, // violet
    {130, 200, 60},  // lime
};
constexpr size_t kPaletteSize = sizeof kPalette / sizeof kPalette[0];
} // namespace

std::span<const Rgb8> participantPalette() {
    return kPalette;
}

uint8_t pickParticipantColour(const std::vector<uint8_t>& inUse) {
    std::array<int, kPaletteSize> worn{};
    for (uint8_t i : inUse)
        if (i < kPaletteSize)
            ++worn[i];
    return uint8_t(std::min_element(worn.begin(), worn.end()) - worn.begin());
}

} // namespace trephine::net
