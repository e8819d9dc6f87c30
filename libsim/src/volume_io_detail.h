// Private plumbing shared by the volume readers and writers (volume_io.cpp, volume_nrrd.cpp,
// volume_nifti.cpp): byte sources and sinks with gzip, scalar decoding through the density window.
#pragma once

#include "libsim/error.h"
#include "libsim/volume.h"
#include "libsim/volume_io.h"

#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <string>

typedef struct z_stream_s z_stream;

namespace trephine::detail {

// Throws Error("<name>: <problem>").
[[noreturn]] void fail(const std::string& name, const std::string& problem);

// [Sources] Sequential readers that count what they delivered.
class ByteSource {
public:
    virtual ~ByteSource() = default;
    // Reads up to n bytes; fewer only at the end of the data. Throws Error on corrupt data.
    size_t read(void* dst, size_t n);
    // Skips up to n bytes; returns how many were skipped.
    uint64_t skip(uint64_t n);
    // Bytes delivered (read or skipped) so far.
    uint64_t position() const { return m_position; }
    const std::string& name() const { return m_name; }

protected:
    explicit ByteSource(std::string name) : m_name(std::move(name)) {}
    virtual size_t readSome(void* dst, size_t n) = 0;

private:
    std::string m_name;
    uint64_t m_position = 0;
};

class FileSource : public ByteSource {
public:
    // Opens path for reading; errors name `name` (the path as the user gave it, usually).
    FileSource(const std::string& path, const std::string& name);
    ~FileSource() override;
    uint64_t size() const { return m_size; }
    // Absolute file offset of the next byte read.
    uint64_t tell() const;
    void seek(uint64_t offset);
    // Reads one header line (without "\n" or "\r\n"). False at end of file. Lines longer than
    // maxLength throw Error.
    bool readLine(std::string& line, size_t maxLength);
    // Skips one line, keeping nothing. False at end of file. Lines longer than maxLength throw
    // Error.
    bool skipLine(size_t maxLength);

protected:
    size_t readSome(void* dst, size_t n) override;

private:
    std::FILE* m_file = nullptr;
    uint64_t m_size = 0;
};

// Inflates gzip (or zlib) data from another source; concatenated gzip members are read as one.
class GzipSource : public ByteSource {
public:
    GzipSource(ByteSource& compressed, const std::string& name);
    ~GzipSource() override;

protected:
    size_t readSome(void* dst, size_t n) override;

private:
    ByteSource& m_in;
    std::unique_ptr<z_stream> m_z;
    std::unique_ptr<uint8_t[]> m_buffer;
    bool m_end = false;
};

bool isGzipMagic(const uint8_t* bytes, size_t n);

// [Sinks]
class ByteSink {
public:
    virtual ~ByteSink() = default;
    virtual void write(const void* data, size_t n) = 0;
    // Flushes everything; a sink that is not finished leaves an incomplete file.
    virtual void finish() = 0;
};

// Writes `path` without ever harming what is there: the bytes go to a temporary file beside it,
// finish() flushes it to the disk, and only commit() renames it over `path`. A sink destroyed
// before its commit (an error, an exception) removes the temporary file and leaves `path` as it
// was. Writers of several files finish them all, then commit them all.
class FileSink : public ByteSink {
public:
    explicit FileSink(const std::string& path);
    ~FileSink() override;
    void write(const void* data, size_t n) override;
    void finish() override;
    void commit();

private:
    std::string m_path, m_temp;
    std::FILE* m_file = nullptr;
    bool m_committed = false;
};

class GzipSink : public ByteSink {
public:
    GzipSink(ByteSink& out, const std::string& name);
    ~GzipSink() override;
    void write(const void* data, size_t n) override;
    void finish() override;

private:
    void pump(int flush);
    ByteSink& m_out;
    std::string m_name;
    std::unique_ptr<z_stream> m_z;
    std::unique_ptr<uint8_t[]> m_buffer;
};

// [Decoding]
enum class ScalarType {
    Int8,
    UInt8,
    Int16,
    UInt16,
    Int32,
    UInt32,
    Int64,
    UInt64,
    Float32,
    Float64
};
size_t scalarSize(ScalarType t);
const char* scalarName(ScalarType t);

struct DecodeSpec {
    ScalarType type = ScalarType::UInt8;
    bool bigEndian = false;
    // 1: a scalar per voxel; 2: our layout, (density, material) uint8 pairs.
    int components = 1;
    // value * slope + inter, then through the window; uint8 with no explicit window and identity
    // scaling passes through unchanged.
    double slope = 1.0;
    double inter = 0.0;
    std::optional<DensityWindow> window;
};

// Checks dimensions against kMaxVolumeVoxels; throws Error naming `name`.
void checkDims(int64_t nx, int64_t ny, int64_t nz, const std::string& name);
uint64_t dataBytes(glm::ivec3 dims, const DecodeSpec& spec);

// Reads exactly dims voxels from src. When `exactEnd`, data left after them is an error
// (dimensions that do not match the data). Errors name src.name().
Volume decodeVoxels(ByteSource& src, glm::ivec3 dims, glm::vec3 spacing, const DecodeSpec& spec,
                    bool exactEnd);

// Before allocating: a raw file must hold exactly `need` bytes after `offset`.
void checkRawSize(const FileSource& file, uint64_t offset, uint64_t need);

// Formats
// A NRRD or NIfTI file, by name or magic; anything else throws Error naming it.
Volume readVolumeFile(const std::string& path, const std::optional<DensityWindow>& window);
Volume readNrrd(const std::string& path, const std::optional<DensityWindow>& window);
Volume readNifti(const std::string& path, const std::optional<DensityWindow>& window);
void writeNrrd(const Volume& v, const std::string& path, bool compress);
// The label value -> segment name table of a 3D Slicer segmentation NRRD's header (empty when it
// has none).
std::map<int, std::string> readNrrdSegmentNames(const std::string& path);
// Label maps: label values 1..kMaxLabelValue (0 is unlabelled), read through the density window
// 0..255 so each value is its own byte.
inline constexpr int kMaxLabelValue = 254;
// Applies the label map `labelsPath` (an integer NRRD or NIfTI of v's dimensions) to v, the names
// from `namesPath` (a colour table: "VALUE NAME [R G B A]" lines) or else from the NRRD's segment
// fields. `spec` names the volume in errors. volume_labels.cpp.
void applyLabelMap(Volume& v, const std::string& labelsPath, const std::string& namesPath,
                   const std::string& spec);
void writeNifti(const Volume& v, const std::string& path, bool compress);

// Number formatting that round-trips a float ("%.9g").
std::string formatFloat(double v);
bool endsWith(const std::string& s, const std::string& suffix);
std::string toLower(std::string s);
// The detached data file a .nhdr header `path` is written with: OUT.raw, or OUT.raw.gz compressed.
std::string detachedDataPath(const std::string& path, bool compress);

inline uint16_t bswap(uint16_t v) {
    return __builtin_bswap16(v);
}
inline uint32_t bswap(uint32_t v) {
    return __builtin_bswap32(v);
}
inline uint64_t bswap(uint64_t v) {
    return __builtin_bswap64(v);
}

} // namespace trephine::detail
