// NRRD (teem's "nearly raw raster data") reading and writing: attached (.nrrd) and detached
// (.nhdr + data file) headers, raw and gzip encodings. We write a 4-D uint8 file of
// (density, material) pairs; we read that and ordinary 3-D scalar volumes. docs/volumes.md.
#include "volume_io_detail.h"

#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <vector>

namespace trephine::detail {

namespace fs = std::filesystem;

namespace {

constexpr const char* kLayoutKey = "trephine_layout";
constexpr const char* kLayoutValue = "density,material";
constexpr size_t kMaxSkippedLine = size_t(1) << 20;

std::string trim(const std::string& s) {
    size_t a = s.find_first_not_of(" \t");
    if (a == std::string::npos)
        return {};
    size_t b = s.find_last_not_of(" \t");
    return s.substr(a, b - a + 1);
}

// A header line quoted in an error: short and printable.
std::string quoteLine(const std::string& line) {
    std::string out;
    for (char c : line.substr(0, 40))
        out.push_back(std::isprint(static_cast<unsigned char>(c)) ? c : '?');
    return "'" + out + (line.size() > 40 ? "...'" : "'");
}

std::vector<std::string> words(const std::string& s) {
    std::vector<std::string> out;
    size_t i = 0;
    while (i < s.size()) {
        while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i])))
            ++i;
        if (i == s.size())
            break;
        size_t start = i;
        if (s[i] == '(') {
            // A vector "(a, b, c)" is one word even with spaces inside.
            while (i < s.size() && s[i] != ')')
                ++i;
            i = std::min(i + 1, s.size());
        } else if (s[i] == '"') {
            i = s.find('"', i + 1);
            i = i == std::string::npos ? s.size() : i + 1;
        } else {
            while (i < s.size() && !std::isspace(static_cast<unsigned char>(s[i])))
                ++i;
        }
        out.push_back(s.substr(start, i - start));
    }
    return out;
}

bool parseDouble(const std::string& s, double& out) {
    if (s.empty())
        return false;
    char* end = nullptr;
    out = std::strtod(s.c_str(), &end);
    return end == s.c_str() + s.size();
}

bool parseInt(const std::string& s, int64_t& out) {
    if (s.empty())
        return false;
    char* end = nullptr;
    errno = 0;
    long long v = std::strtoll(s.c_str(), &end, 10);
    out = v;
    return errno == 0 && end == s.c_str() + s.size();
}

std::optional<ScalarType> nrrdType(const std::string& t) {
    static const std::map<std::string, ScalarType> kTypes = {
        {"signed char", ScalarType::Int8},
        {"int8", ScalarType::Int8},
        {"int8_t", ScalarType::Int8},
        {"char", ScalarType::Int8},
        {"uchar", ScalarType::UInt8},
        {"unsigned char", ScalarType::UInt8},
        {"uint8", ScalarType::UInt8},
        {"uint8_t", ScalarType::UInt8},
        {"short", ScalarType::Int16},
        {"short int", ScalarType::Int16},
        {"signed short", ScalarType::Int16},
        {"signed short int", ScalarType::Int16},
        {"int16", ScalarType::Int16},
        {"int16_t", ScalarType::Int16},
        {"ushort", ScalarType::UInt16},
        {"unsigned short", ScalarType::UInt16},
        {"unsigned short int", ScalarType::UInt16},
        {"uint16", ScalarType::UInt16},
        {"uint16_t", ScalarType::UInt16},
        {"int", ScalarType::Int32},
        {"signed int", ScalarType::Int32},
        {"int32", ScalarType::Int32},
        {"int32_t", ScalarType::Int32},
        {"uint", ScalarType::UInt32},
        {"unsigned int", ScalarType::UInt32},
        {"uint32", ScalarType::UInt32},
        {"uint32_t", ScalarType::UInt32},
        {"longlong", ScalarType::Int64},
        {"long long", ScalarType::Int64},
        {"long long int", ScalarType::Int64},
        {"signed long long", ScalarType::Int64},
        {"signed long long int", ScalarType::Int64},
        {"int64", ScalarType::Int64},
        {"int64_t", ScalarType::Int64},
        {"ulonglong", ScalarType::UInt64},
        {"unsigned long long", ScalarType::UInt64},
        {"unsigned long long int", ScalarType::UInt64},
        {"uint64", ScalarType::UInt64},
        {"uint64_t", ScalarType::UInt64},
        {"float", ScalarType::Float32},
        {"double", ScalarType::Float64},
    };
    auto it = kTypes.find(t);
    if (it == kTypes.end())
        return std::nullopt;
    return it->second;
}

// mm per unit of a "space units" entry; 0 when unknown.
double unitScale(std::string u) {
    if (u.size() >= 2 && u.front() == '"' && u.back() == '"')
        u = u.substr(1, u.size() - 2);
    u = toLower(u);
    if (u == "mm" || u == "millimeter" || u == "millimeters" || u.empty())
        return 1.0;
    if (u == "cm")
        return 10.0;
    if (u == "m" || u == "meter" || u == "meters")
        return 1000.0;
    if (u == "um" || u == "micron" || u == "microns")
        return 0.001;
    return 0.0;
}

struct Header {
    std::map<std::string, std::string> fields;
    std::map<std::string, std::string> keyValues;
    bool blankLine = false; // data follows in this file

    const std::string* find(const std::string& key) const {
        auto it = fields.find(key);
        return it == fields.end() ? nullptr : &it->second;
    }
};

Header readHeader(FileSource& file, const std::string& path) {
    std::string line;
    if (!file.readLine(line, 64))
        fail(path, "empty file: not a NRRD file");
    if (line.size() != 8 || line.compare(0, 7, "NRRD000") != 0 || !std::isdigit(line[7]))
        fail(path, "not a NRRD file: the first line must be NRRD000X, found " + quoteLine(line));
    Header h;
    size_t total = 0;
    while (file.readLine(line, 1 << 16)) {
        total += line.size() + 1;
        if (total > (1u << 20))
            fail(path, "NRRD header larger than 1 MiB: missing the blank line before the data?");
        if (line.empty()) {
            h.blankLine = true;
            break;
        }
        if (line[0] == '#')
            continue;
        size_t kv = line.find(":=");
        size_t colon = line.find(": ");
        if (kv != std::string::npos && (colon == std::string::npos || kv < colon)) {
            h.keyValues[line.substr(0, kv)] = line.substr(kv + 2);
            continue;
        }
        if (colon == std::string::npos)
            fail(path, "bad NRRD header line " + quoteLine(line) + ": expected 'field: value'");
        std::string field = toLower(trim(line.substr(0, colon)));
        if (field == "datafile")
            field = "data file";
        else if (field == "byteskip")
            field = "byte skip";
        else if (field == "lineskip")
            field = "line skip";
        else if (field == "centerings")
            field = "centers";
        if (h.fields.count(field))
            fail(path, "NRRD field '" + field + "' given twice");
        h.fields[field] = trim(line.substr(colon + 2));
    }
    return h;
}

const std::string& required(const Header& h, const std::string& field, const std::string& path) {
    const std::string* v = h.find(field);
    if (!v)
        fail(path, "missing NRRD field '" + field + "'");
    return *v;
}

// Length of each domain axis' space direction, or the spacings field, or 1.
glm::vec3 readSpacing(const Header& h, const std::string& path, int dimension,
                      const std::vector<int>& axes) {
    glm::dvec3 spacing(1.0);
    if (const std::string* dirs = h.find("space directions")) {
        std::vector<std::string> w = words(*dirs);
        if (int(w.size()) != dimension)
            fail(path, "bad NRRD 'space directions': expected " + std::to_string(dimension) +
                           " entries, found " + std::to_string(w.size()));
        for (size_t i = 0; i < axes.size(); ++i) {
            const std::string& v = w[size_t(axes[i])];
            if (v.size() < 2 || v.front() != '(' || v.back() != ')')
                fail(path, "bad NRRD 'space directions' entry '" + v +
                               "' for a spatial axis: expected (a,b,c)");
            double sum = 0.0;
            size_t start = 1;
            while (start < v.size()) {
                size_t end = v.find_first_of(",)", start);
                double c;
                if (!parseDouble(trim(v.substr(start, end - start)), c) || !std::isfinite(c))
                    fail(path, "bad NRRD 'space directions' entry '" + v + "'");
                sum += c * c;
                start = end + 1;
            }
            if (!(sum > 0.0))
                fail(path, "bad NRRD 'space directions' entry '" + v + "': zero length");
            spacing[int(i)] = std::sqrt(sum);
        }
        if (const std::string* units = h.find("space units")) {
            const std::vector<std::string> u = words(*units);
            for (size_t i = 0; i < axes.size() && i < u.size(); ++i) {
                double scale = unitScale(u[i]);
                if (scale == 0.0)
                    fail(path, "unknown NRRD 'space units' " + u[i] + ": expected mm, cm, m or um");
                spacing[int(i)] *= scale;
            }
        }
    } else if (const std::string* sp = h.find("spacings")) {
        std::vector<std::string> w = words(*sp);
        if (int(w.size()) != dimension)
            fail(path, "bad NRRD 'spacings': expected " + std::to_string(dimension) +
                           " numbers, found " + std::to_string(w.size()));
        for (size_t i = 0; i < axes.size(); ++i) {
            const std::string& v = w[size_t(axes[i])];
            double s;
            // A spatial axis needs a size: NaN (NRRD's "unknown") or 0 would load as 1 mm.
            if (!parseDouble(v, s) || !std::isfinite(s) || s == 0.0)
                fail(path, "bad NRRD 'spacings' entry '" + v +
                               "' for a spatial axis: expected a finite, non-zero size in mm");
            spacing[int(i)] = std::fabs(s);
        }
    }
    glm::vec3 out(spacing);
    for (int i = 0; i < 3; ++i)
        if (!(out[i] > 0.0f) || !std::isfinite(out[i]))
            fail(path, "bad NRRD spacing " + formatFloat(spacing[i]));
    return out;
}

} // namespace

Volume readNrrd(const std::string& path, const std::optional<DensityWindow>& window) {
    FileSource file(path, path);
    Header h = readHeader(file, path);

    DecodeSpec spec;
    spec.window = window;
    const std::string& typeText = required(h, "type", path);
    std::optional<ScalarType> type = nrrdType(typeText);
    if (!type)
        fail(path, "unsupported NRRD type '" + typeText +
                       "' (expected uchar, char, short, ushort, int, uint, float or double)");
    spec.type = *type;

    int64_t dimension;
    const std::string& dimText = required(h, "dimension", path);
    if (!parseInt(dimText, dimension) || dimension < 1 || dimension > 16)
        fail(path, "bad NRRD dimension '" + dimText + "'");
    const std::string& sizesText = required(h, "sizes", path);
    std::vector<int64_t> sizes;
    for (const std::string& w : words(sizesText)) {
        int64_t s;
        if (!parseInt(w, s) || s <= 0)
            fail(path, "bad NRRD sizes '" + sizesText + "': expected positive integers");
        sizes.push_back(s);
    }
    if (int64_t(sizes.size()) != dimension)
        fail(path, "bad NRRD sizes '" + sizesText + "': dimension is " + std::to_string(dimension) +
                       " but " + std::to_string(sizes.size()) + " sizes are given");

    // Which axes are x, y, z; a leading axis of 2 in our layout holds (density, material).
    auto layout = h.keyValues.find(kLayoutKey);
    const bool ours = layout != h.keyValues.end() && layout->second == kLayoutValue;
    std::vector<int> axes;
    if (ours) {
        if (dimension != 4 || sizes[0] != 2 || spec.type != ScalarType::UInt8)
            fail(path, std::string(kLayoutKey) + ":=" + kLayoutValue +
                           " needs type uchar, dimension 4 and sizes 2 X Y Z");
        spec.components = 2;
        axes = {1, 2, 3};
    } else if (dimension == 3) {
        axes = {0, 1, 2};
    } else if (dimension == 2) {
        axes = {0, 1};
    } else if (dimension == 4 && sizes[0] == 1) {
        axes = {1, 2, 3};
    } else if (dimension == 4 && sizes[3] == 1) {
        axes = {0, 1, 2};
    } else if (dimension == 4) {
        fail(path, "4-D NRRD with " + std::to_string(sizes[0]) +
                       " values per voxel is not supported: expected a 3-D scalar volume");
    } else {
        fail(path, "NRRD dimension " + std::to_string(dimension) +
                       " is not supported: expected a 3-D volume");
    }
    int64_t n[3] = {1, 1, 1};
    for (size_t i = 0; i < axes.size(); ++i)
        n[i] = sizes[size_t(axes[i])];
    checkDims(n[0], n[1], n[2], path);
    glm::ivec3 dims{int(n[0]), int(n[1]), int(n[2])};

    if (scalarSize(spec.type) > 1) {
        const std::string* endian = h.find("endian");
        if (!endian)
            fail(path, "missing NRRD field 'endian' (needed for type " + typeText + ")");
        if (*endian != "little" && *endian != "big")
            fail(path, "bad NRRD endian '" + *endian + "': expected little or big");
        spec.bigEndian = *endian == "big";
    }

    const std::string encoding = toLower(required(h, "encoding", path));
    const bool gzip = encoding == "gzip" || encoding == "gz";
    if (!gzip && encoding != "raw")
        fail(path, "unsupported NRRD encoding '" + encoding + "' (trephine reads raw and gzip)");

    glm::vec3 spacing = readSpacing(h, path, int(dimension), axes);

    int64_t lineSkip = 0, byteSkip = 0;
    if (const std::string* ls = h.find("line skip");
        ls && (!parseInt(*ls, lineSkip) || lineSkip < 0))
        fail(path, "bad NRRD line skip '" + *ls + "'");
    if (const std::string* bs = h.find("byte skip");
        bs && (!parseInt(*bs, byteSkip) || byteSkip < -1))
        fail(path, "bad NRRD byte skip '" + *bs + "'");
    if (byteSkip == -1 && gzip)
        fail(path, "NRRD byte skip -1 only works with raw encoding");

    std::unique_ptr<FileSource> detached;
    FileSource* data = &file;
    if (const std::string* df = h.find("data file")) {
        if (df->rfind("LIST", 0) == 0 || words(*df).size() > 1)
            fail(path, "multi-file NRRD data ('data file: " + *df + "') is not supported");
        fs::path dataPath = *df;
        if (dataPath.is_relative())
            dataPath = fs::path(path).parent_path() / dataPath;
        detached = std::make_unique<FileSource>(dataPath.string(), dataPath.string());
        data = detached.get();
    } else if (!h.blankLine) {
        fail(path, "truncated: the NRRD header ends without data (no blank line and no "
                   "'data file' field)");
    }

    // Skipped lines are text (a header before the data): kept nowhere and at most 1 MiB each, so
    // a line skip over binary data fails fast (it read up to 1 GiB into memory: 2 GB and 23 s for
    // `data file: /dev/zero`).
    for (int64_t i = 0; i < lineSkip; ++i)
        if (!data->skipLine(kMaxSkippedLine))
            fail(data->name(),
                 "truncated: shorter than NRRD line skip " + std::to_string(lineSkip));
    const uint64_t need = dataBytes(dims, spec);
    if (gzip) {
        GzipSource gz(*data, data->name());
        if (gz.skip(uint64_t(byteSkip)) < uint64_t(byteSkip))
            fail(data->name(),
                 "truncated: shorter than NRRD byte skip " + std::to_string(byteSkip));
        return decodeVoxels(gz, dims, spacing, spec, true);
    }
    uint64_t offset = data->tell();
    if (byteSkip == -1) {
        if (data->size() < offset + need)
            fail(data->name(),
                 "truncated: expected " + std::to_string(need) + " bytes of data, found " +
                     std::to_string(data->size() > offset ? data->size() - offset : 0));
        offset = data->size() - need;
    } else {
        offset += uint64_t(byteSkip);
    }
    checkRawSize(*data, offset, need);
    data->seek(offset);
    return decodeVoxels(*data, dims, spacing, spec, true);
}

std::map<int, std::string> readNrrdSegmentNames(const std::string& path) {
    FileSource file(path, path);
    const Header h = readHeader(file, path);
    // 3D Slicer's segmentation fields: SegmentK_Name and SegmentK_LabelValue (K from 0).
    std::map<int, std::string> names;
    for (int k = 0;; ++k) {
        const std::string prefix = "Segment" + std::to_string(k) + "_";
        auto name = h.keyValues.find(prefix + "Name");
        if (name == h.keyValues.end())
            break;
        int64_t value = k + 1;
        auto label = h.keyValues.find(prefix + "LabelValue");
        if (label != h.keyValues.end() &&
            (!parseInt(trim(label->second), value) || value < 1 || value > kMaxLabelValue))
            fail(path, prefix + "LabelValue '" + label->second + "' is not a label from 1 to " +
                           std::to_string(kMaxLabelValue));
        names[int(value)] = trim(name->second);
    }
    return names;
}

void writeNrrd(const Volume& v, const std::string& path, bool compress) {
    const bool detachedData = endsWith(toLower(path), ".nhdr");
    const std::string dataPath = detachedData ? detachedDataPath(path, compress) : path;

    const glm::ivec3 d = v.dims();
    const glm::vec3 s = v.spacing();
    const glm::vec3 origin = v.voxelCenter(glm::ivec3(0));
    std::string materials;
    for (int m = 0; m < kMaterialCount; ++m) {
        if (m)
            materials += ';';
        materials += std::to_string(m);
        materials += ' ';
        materials += materialName(Material(m));
    }
    std::string header = "NRRD0004\n"
                         "# Trephine volume: (density, material) uint8 pairs per voxel, x fastest\n"
                         "type: uint8\n"
                         "dimension: 4\n"
                         "space dimension: 3\n"
                         "sizes: 2 " +
                         std::to_string(d.x) + " " + std::to_string(d.y) + " " +
                         std::to_string(d.z) + "\nspace directions: none (" + formatFloat(s.x) +
                         ",0,0) (0," + formatFloat(s.y) + ",0) (0,0," + formatFloat(s.z) +
                         ")\n"
                         "space units: \"mm\" \"mm\" \"mm\"\n"
                         "space origin: (" +
                         formatFloat(origin.x) + "," + formatFloat(origin.y) + "," +
                         formatFloat(origin.z) +
                         ")\n"
                         "kinds: vector domain domain domain\n"
                         "centers: ??? cell cell cell\n"
                         "endian: little\n"
                         "encoding: " +
                         std::string(compress ? "gzip" : "raw") + "\n";
    if (detachedData)
        header += "data file: " + fs::path(dataPath).filename().string() + "\n";
    header += std::string(kLayoutKey) + ":=" + kLayoutValue + "\n";
    header += "trephine_materials:=" + materials + "\n";

    // Temporary files, renamed over the targets only once both are complete (FileSink): a
    // failure leaves whatever was there before untouched.
    FileSink headerSink(path);
    headerSink.write(header.data(), header.size());
    std::unique_ptr<FileSink> dataFile;
    ByteSink* out = &headerSink;
    if (detachedData) {
        headerSink.finish();
        dataFile = std::make_unique<FileSink>(dataPath);
        out = dataFile.get();
    } else {
        headerSink.write("\n", 1);
    }
    std::unique_ptr<GzipSink> gz;
    if (compress) {
        gz = std::make_unique<GzipSink>(*out, dataPath);
        out = gz.get();
    }
    const size_t voxels = v.voxelCount();
    constexpr size_t kChunk = size_t(1) << 16;
    std::vector<uint8_t> pairs(2 * kChunk);
    for (size_t i = 0; i < voxels; i += kChunk) {
        size_t n = std::min(kChunk, voxels - i);
        for (size_t k = 0; k < n; ++k) {
            pairs[2 * k] = v.densityData()[i + k];
            pairs[2 * k + 1] = v.materialData()[i + k];
        }
        out->write(pairs.data(), 2 * n);
    }
    out->finish();
    if (dataFile)
        dataFile->commit();
    headerSink.commit();
}

} // namespace trephine::detail
