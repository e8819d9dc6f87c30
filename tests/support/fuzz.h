// Shared by the mutation fuzz tests (decoders, volume readers, image readers): deterministic byte
// mutations, hostile field values, the TREPHINE_FUZZ_SCALE knob, an in-memory scratch folder, and
// a probe of the largest single allocation.
//
// The probe needs the test binary's operator new replaced: expand TREPHINE_FUZZ_ALLOCATION_PROBE
// once, at namespace scope, in exactly one source file of a test binary.
#pragma once

#include "libsim/error.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <new>
#include <random>
#include <string>
#include <system_error>
#include <unistd.h>
#include <vector>

namespace trephine::testing {

using Bytes = std::vector<uint8_t>; // as in byte_files.h

// TREPHINE_FUZZ_SCALE=N runs N times as many mutations (default 1: a fast run for CI).
inline int fuzzScale() {
    const char* s = std::getenv("TREPHINE_FUZZ_SCALE");
    const int n = s ? std::atoi(s) : 1;
    return std::max(n, 1);
}

// Values a hostile input puts in a size, count or offset field.
inline constexpr uint64_t kSpecialValues[] = {0,          1,          0x7f,       0x80,
                                              0xff,       0x7fff,     0x8000,     0xffff,
                                              0x7fffffff, 0x80000000, 0xffffffff, ~uint64_t(0)};

inline void writeLittleEndian(Bytes& b, size_t at, uint64_t v, size_t width) {
    for (size_t i = 0; i < width && at + i < b.size(); ++i)
        b[at + i] = uint8_t(v >> (8 * i));
}

inline void writeBigEndian(Bytes& b, size_t at, uint64_t v, size_t width) {
    for (size_t i = 0; i < width && at + i < b.size(); ++i)
        b[at + i] = uint8_t(v >> (8 * (width - 1 - i)));
}

// Deterministic edits of a byte string (std::mt19937 is the same sequence everywhere; the
// distributions are not, so draws use plain modulo).
class Mutator {
public:
    explicit Mutator(uint32_t seed) : m_rng(seed) {}

    uint32_t below(uint32_t n) { return n ? uint32_t(m_rng() % n) : 0; }

    Bytes mutate(Bytes b) {
        const uint32_t edits = 1 + below(4);
        for (uint32_t e = 0; e < edits; ++e) {
            const size_t at = below(uint32_t(b.size()));
            switch (below(8)) {
            case 0: // flip a bit
                if (!b.empty())
                    b[at] ^= uint8_t(1u << below(8));
                break;
            case 1: // a random byte
                if (!b.empty())
                    b[at] = uint8_t(m_rng());
                break;
            case 2: { // a hostile value in a field of 1, 2, 4 or 8 bytes, either byte order
                const uint64_t v = kSpecialValues[below(std::size(kSpecialValues))];
                const size_t width = size_t(1) << below(4);
                if (below(2))
                    writeLittleEndian(b, at, v, width);
                else
                    writeBigEndian(b, at, v, width);
                break;
            }
            case 3: // truncated
                b.resize(below(uint32_t(b.size()) + 1));
                break;
            case 4: { // bytes inserted
                Bytes ins(1 + below(8));
                for (uint8_t& v : ins)
                    v = uint8_t(m_rng());
                b.insert(b.begin() + std::ptrdiff_t(at), ins.begin(), ins.end());
                break;
            }
            case 5: // bytes deleted
                b.erase(b.begin() + std::ptrdiff_t(at),
                        b.begin() + std::ptrdiff_t(std::min(b.size(), at + 1 + below(8))));
                break;
            case 6: // a run copied over another place (repeated structure)
                if (b.size() > 2) {
                    const size_t from = below(uint32_t(b.size())), n = 1 + below(16);
                    for (size_t i = 0; i < n && from + i < b.size() && at + i < b.size(); ++i)
                        b[at + i] = b[from + i];
                }
                break;
            default: // appended junk
                b.push_back(uint8_t(m_rng()));
                break;
            }
        }
        return b;
    }

private:
    std::mt19937 m_rng;
};

// A fresh folder, removed with everything in it on destruction: in memory (/dev/shm) unless TMPDIR
// says otherwise, since thousands of small files written to a disk-backed /tmp take seconds.
struct FuzzDir {
    std::filesystem::path path;
    FuzzDir() {
        namespace fs = std::filesystem;
        static int counter = 0;
        std::error_code ec;
        fs::path base = fs::temp_directory_path();
        if (!std::getenv("TMPDIR") && fs::is_directory("/dev/shm", ec) &&
            ::access("/dev/shm", W_OK) == 0)
            base = "/dev/shm";
        path = base /
               ("trephine_fuzz_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
        fs::remove_all(path, ec);
        fs::create_directories(path);
    }
    ~FuzzDir() {
        std::error_code ec;
        std::filesystem::remove_all(path, ec);
    }
    FuzzDir(const FuzzDir&) = delete;
    FuzzDir& operator=(const FuzzDir&) = delete;
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// The largest single allocation this thread makes while a probe is alive (see
// TREPHINE_FUZZ_ALLOCATION_PROBE).
inline thread_local bool t_probing = false;
inline thread_local size_t t_largestAllocation = 0;

struct AllocationProbe {
    AllocationProbe() { t_probing = true, t_largestAllocation = 0; }
    ~AllocationProbe() { t_probing = false; }
    size_t largest() const { return t_largestAllocation; }
};

// Runs f expecting a one-line trephine::Error containing `problem`; returns the largest single
// allocation f made.
template <typename F>
size_t expectRefused(F&& f, const std::string& problem) {
    AllocationProbe probe;
    try {
        f();
        ADD_FAILURE() << "no Error; expected one saying '" << problem << "'";
    } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(problem), std::string::npos) << msg;
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
    return probe.largest();
}

} // namespace trephine::testing

// The test binary's operator new and delete: malloc and free, the size noted while a probe is
// alive. (GCC sees free() on what operator new returned and warns; here they are one malloc and
// free.)
#if defined(__GNUC__) && !defined(__clang__)
#define TREPHINE_FUZZ_IGNORE_NEW_DELETE                                                            \
    _Pragma("GCC diagnostic ignored \"-Wmismatched-new-delete\"")
#else
#define TREPHINE_FUZZ_IGNORE_NEW_DELETE
#endif
#define TREPHINE_FUZZ_ALLOCATION_PROBE()                                                           \
    TREPHINE_FUZZ_IGNORE_NEW_DELETE                                                                \
    void* operator new(size_t n) {                                                                 \
        if (trephine::testing::t_probing)                                                          \
            trephine::testing::t_largestAllocation =                                               \
                std::max(trephine::testing::t_largestAllocation, n);                               \
        if (void* p = std::malloc(n ? n : 1))                                                      \
            return p;                                                                              \
        throw std::bad_alloc();                                                                    \
    }                                                                                              \
    void operator delete(void* p) noexcept {                                                       \
        std::free(p);                                                                              \
    }                                                                                              \
    void operator delete(void* p, size_t) noexcept {                                               \
        std::free(p);                                                                              \
    }
