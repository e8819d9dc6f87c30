// Private to sim_image: how large an image an image file can honestly claim to hold.
#pragma once

#include <cstdint>

namespace trephine::detail {

// A header's width, height and channels are only a claim; the pixels must come from the file.
// Deflate (PNG, TIFF, OpenEXR zip) packs at most 1032:1, and 1-bit pixels unpacked to bytes 8
// times more: a file that claims more than 8256 bytes of pixels per byte it holds is corrupt or
// hostile. Claims up to 16 MiB are taken as they are, for codecs that pack blank images tighter.
inline constexpr uint64_t kMaxImageBytesPerFileByte = 8256;
inline constexpr uint64_t kAlwaysPlausibleImageBytes = uint64_t(16) << 20;

inline bool plausibleImageBytes(uint64_t imageBytes, uint64_t fileBytes) {
    return imageBytes <= kAlwaysPlausibleImageBytes ||
           imageBytes / kMaxImageBytesPerFileByte <= fileBytes;
}

} // namespace trephine::detail
