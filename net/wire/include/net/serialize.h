// Bit-exact, bounds-checked (de)serialisation after yojimbo's pattern: one
// `template <typename Stream> bool serialize(Stream&)` per message is the writer, the reader and
// the size. Integers are little-endian. Every read checks length and range and returns false on
// a malformed input; nothing here asserts on wire data.
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace trephine::net {

namespace detail {
template <typename T, bool = std::is_enum_v<T>>
struct WireInteger {
    using type = std::make_unsigned_t<T>;
};
template <typename T>
struct WireInteger<T, true> {
    using type = std::make_unsigned_t<std::underlying_type_t<T>>;
};
} // namespace detail

// The unsigned integer an integer or enum travels as.
template <typename T>
using WireUnsigned = typename detail::WireInteger<T>::type;

// GCC 12 reports false stringop-overflow/overread warnings for vector growth inlined here
// (GCC bug 106199); the sizes are checked.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstringop-overflow"
#pragma GCC diagnostic ignored "-Wstringop-overread"
#endif

// Writes into a growing byte vector.
class WriteStream {
public:
    static constexpr bool kWriting = true;
    static constexpr bool kReading = false;

    explicit WriteStream(std::vector<uint8_t>& out) : m_out(out) {}

    template <typename T>
    requires std::is_integral_v<T> || std::is_enum_v<T>
    bool integer(T& v) {
        using U = WireUnsigned<T>;
        U u = static_cast<U>(v);
        for (size_t i = 0; i < sizeof(U); ++i)
            m_out.push_back(uint8_t(u >> (8 * i)));
        return true;
    }
    template <typename T>
    bool ranged(T& v, T lo, T hi) {
        return v >= lo && v <= hi && integer(v);
    }
    bool f32(float& v) {
        uint32_t bits;
        std::memcpy(&bits, &v, 4);
        return integer(bits);
    }
    bool f64(double& v) {
        uint64_t bits;
        std::memcpy(&bits, &v, 8);
        return integer(bits);
    }
    bool boolean(bool& v) {
        uint8_t b = v ? 1 : 0;
        return integer(b);
    }
    bool bytes(uint8_t* data, size_t n) {
        if (n == 0)
            return true;
        size_t at = m_out.size();
        m_out.resize(at + n);
        std::memcpy(m_out.data() + at, data, n);
        return true;
    }
    // u32 length prefix, then the bytes; refuses to write more than maxSize.
    bool blob(std::vector<uint8_t>& v, size_t maxSize) {
        if (v.size() > maxSize)
            return false;
        uint32_t n = uint32_t(v.size());
        return integer(n) && bytes(v.data(), v.size());
    }
    bool string(std::string& s, size_t maxSize) {
        if (s.size() > maxSize)
            return false;
        uint16_t n = uint16_t(s.size());
        return integer(n) && bytes(reinterpret_cast<uint8_t*>(s.data()), s.size());
    }

private:
    std::vector<uint8_t>& m_out;
};

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// Reads from a byte span; every read is bounds-checked.
class ReadStream {
public:
    static constexpr bool kWriting = false;
    static constexpr bool kReading = true;

    explicit ReadStream(std::span<const uint8_t> in) : m_in(in) {}

    template <typename T>
    requires std::is_integral_v<T> || std::is_enum_v<T>
    bool integer(T& v) {
        using U = WireUnsigned<T>;
        if (remaining() < sizeof(U))
            return false;
        U u = 0;
        for (size_t i = 0; i < sizeof(U); ++i)
            u |= U(U(m_in[m_pos + i]) << (8 * i));
        m_pos += sizeof(U);
        v = static_cast<T>(u);
        return true;
    }
    template <typename T>
    bool ranged(T& v, T lo, T hi) {
        return integer(v) && v >= lo && v <= hi;
    }
    bool f32(float& v) {
        uint32_t bits;
        if (!integer(bits))
            return false;
        std::memcpy(&v, &bits, 4);
        return true;
    }
    bool f64(double& v) {
        uint64_t bits;
        if (!integer(bits))
            return false;
        std::memcpy(&v, &bits, 8);
        return true;
    }
    bool boolean(bool& v) {
        uint8_t b;
        if (!integer(b) || b > 1)
            return false;
        v = b != 0;
        return true;
    }
    bool bytes(uint8_t* data, size_t n) {
        if (remaining() < n)
            return false;
        std::memcpy(data, m_in.data() + m_pos, n);
        m_pos += n;
        return true;
    }
    bool blob(std::vector<uint8_t>& v, size_t maxSize) {
        uint32_t n;
        if (!integer(n) || n > maxSize || n > remaining())
            return false;
        v.assign(m_in.begin() + m_pos, m_in.begin() + m_pos + n);
        m_pos += n;
        return true;
    }
    bool string(std::string& s, size_t maxSize) {
        uint16_t n;
        if (!integer(n) || n > maxSize || n > remaining())
            return false;
        s.assign(reinterpret_cast<const char*>(m_in.data() + m_pos), n);
        m_pos += n;
        return true;
    }

    size_t remaining() const { return m_in.size() - m_pos; }
    bool atEnd() const { return m_pos == m_in.size(); }

private:
    std::span<const uint8_t> m_in;
    size_t m_pos = 0;
};

// Counts bytes without writing: the size of a message for budgeting.
class MeasureStream {
public:
    static constexpr bool kWriting = true;
    static constexpr bool kReading = false;

    template <typename T>
    bool integer(T&) {
        m_bytes += sizeof(T);
        return true;
    }
    template <typename T>
    bool ranged(T& v, T, T) {
        return integer(v);
    }
    bool f32(float&) { return m_bytes += 4, true; }
    bool f64(double&) { return m_bytes += 8, true; }
    bool boolean(bool&) { return m_bytes += 1, true; }
    bool bytes(uint8_t*, size_t n) { return m_bytes += n, true; }
    bool blob(std::vector<uint8_t>& v, size_t) { return m_bytes += 4 + v.size(), true; }
    bool string(std::string& s, size_t) { return m_bytes += 2 + s.size(), true; }

    size_t size() const { return m_bytes; }

private:
    size_t m_bytes = 0;
};

} // namespace trephine::net
