// Bytes in and out of files for the file-format tests: whole-file reads and writes, values in a
// chosen byte order, gzip, and a NIfTI-1 header.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/vec3.hpp>
#include <iterator>
#include <string>
#include <system_error>
#include <vector>
#include <zlib.h>

namespace trephine::testing {

using Bytes = std::vector<uint8_t>;

// Replaces the file by a new one: truncating it in place would make ext4 flush it to the disk on
// close (its guard for files rewritten in place), a thousand times slower in a fuzz loop.
inline void writeFile(const std::string& path, const Bytes& data) {
    std::error_code ec;
    std::filesystem::remove(path, ec);
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(data.data()), std::streamsize(data.size()));
}

inline Bytes readFile(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return Bytes(std::istreambuf_iterator<char>(f), {});
}

// Values as bytes in the given order.
template <typename T>
Bytes encode(const std::vector<T>& values, bool bigEndian) {
    Bytes out;
    for (T v : values) {
        uint8_t b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        if (bigEndian)
            std::reverse(b, b + sizeof(T));
        out.insert(out.end(), b, b + sizeof(T));
    }
    return out;
}

// A gzip stream (header and trailer) of `data`.
inline Bytes gzip(const Bytes& data) {
    z_stream z{};
    deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
    Bytes out(deflateBound(&z, uLong(data.size())) + 64);
    z.next_in = const_cast<Bytef*>(data.data());
    z.avail_in = uInt(data.size());
    z.next_out = out.data();
    z.avail_out = uInt(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

// A single-file NIfTI-1 header (352 bytes with the empty extension block).
inline Bytes niftiHeader(glm::ivec3 dims, int16_t datatype, int16_t bitpix, glm::vec3 pixdim,
                         float slope, float inter, bool bigEndian) {
    Bytes h(352, 0);
    auto put = [&](size_t off, auto v) {
        uint8_t b[sizeof v];
        std::memcpy(b, &v, sizeof v);
        if (bigEndian)
            std::reverse(b, b + sizeof v);
        std::memcpy(h.data() + off, b, sizeof v);
    };
    put(0, int32_t(348));
    const int16_t dim[8] = {3, int16_t(dims.x), int16_t(dims.y), int16_t(dims.z), 1, 1, 1, 1};
    for (int i = 0; i < 8; ++i)
        put(40 + 2 * size_t(i), dim[i]);
    put(70, datatype);
    put(72, bitpix);
    const float pd[4] = {1.0f, pixdim.x, pixdim.y, pixdim.z};
    for (int i = 0; i < 4; ++i)
        put(76 + 4 * size_t(i), pd[i]);
    put(108, 352.0f);
    put(112, slope);
    put(116, inter);
    h[123] = 2;
    std::memcpy(h.data() + 344, "n+1", 4);
    return h;
}

} // namespace trephine::testing
