#include "libsim_image/dbi_io.h"

#include "libsim/error.h"
#include "libsim/replacing_file.h"

#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <vector>

namespace trephine {

namespace {

// OpenImageIO's messages can run over several lines; a user error is one line.
std::string firstLine(std::string s) {
    size_t nl = s.find('\n');
    if (nl != std::string::npos)
        s.resize(nl);
    return s.empty() ? "unknown error" : s;
}

bool hasExtension(const std::string& path, std::initializer_list<const char*> exts) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    for (const char* e : exts)
        if (ext == e)
            return true;
    return false;
}

// The size of an OpenEXR attribute type's value, or -1 for types of any size.
int fixedSize(const std::string& type) {
    static const std::pair<const char*, int> kSizes[] = {
        {"box2i", 16},    {"box2f", 16},   {"compression", 1},
        {"lineOrder", 1}, {"envmap", 1},   {"deepImageState", 1},
        {"float", 4},     {"double", 8},   {"int", 4},
        {"v2i", 8},       {"v2f", 8},      {"v2d", 16},
        {"v3i", 12},      {"v3f", 12},     {"v3d", 24},
        {"m33f", 36},     {"m33d", 72},    {"m44f", 64},
        {"m44d", 128},    {"rational", 8}, {"keycode", 28},
        {"timecode", 8},  {"tiledesc", 9}, {"chromaticities", 32},
    };
    for (const auto& [name, size] : kSizes)
        if (type == name)
            return size;
    return -1;
}

// OpenEXR allocates each header attribute's declared size before reading its value (a 597-byte
// file whose 'Software' string claimed 2 GiB allocated 2 GiB), so the sizes are checked against
// the file first. Returns the problem, or "" when the header is sound or not OpenEXR at all (then
// OpenImageIO says what it is).
std::string exrHeaderProblem(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    uint8_t head[8];
    if (!f.read(reinterpret_cast<char*>(head), sizeof head) ||
        std::memcmp(head, "\x76\x2f\x31\x01", 4) != 0)
        return {};
    std::error_code ec;
    const uint64_t fileBytes = std::filesystem::file_size(path, ec);
    if (ec)
        return {};
    auto readName = [&](std::string& out) {
        out.clear();
        char c;
        while (f.get(c) && c != '\0' && out.size() <= 255)
            out.push_back(std::isprint(static_cast<unsigned char>(c)) ? c : '?'); // one line
        return bool(f) && c == '\0';
    };
    std::string name, type;
    // The first (a DBI's only) header: attributes up to an empty name.
    while (true) {
        if (!readName(name))
            return "corrupt OpenEXR header: truncated or an attribute name too long";
        if (name.empty())
            return {};
        if (!readName(type))
            return "corrupt OpenEXR header: attribute '" + name + "' has no type";
        uint8_t sizeBytes[4];
        if (!f.read(reinterpret_cast<char*>(sizeBytes), 4))
            return "corrupt OpenEXR header: truncated in attribute '" + name + "'";
        const int32_t size = int32_t(uint32_t(sizeBytes[0]) | uint32_t(sizeBytes[1]) << 8 |
                                     uint32_t(sizeBytes[2]) << 16 | uint32_t(sizeBytes[3]) << 24);
        const uint64_t at = uint64_t(f.tellg());
        if (size < 0 || at + uint64_t(size) > fileBytes)
            return "corrupt OpenEXR header: attribute '" + name + "' claims " +
                   std::to_string(size) + " bytes, the file holds " +
                   std::to_string(fileBytes > at ? fileBytes - at : 0) + " more";
        // OpenEXR reads a value of a fixed-size type whatever its declared size, and takes the
        // bytes after it as the next attribute: any other size puts it out of step with this
        // check (a 'compression' of 129 bytes hid an attribute that claimed 1.7 GB).
        if (const int fixed = fixedSize(type); fixed >= 0 && size != fixed)
            return "corrupt OpenEXR header: attribute '" + name + "' of type " + type + " has " +
                   std::to_string(size) + " bytes, expected " + std::to_string(fixed);
        // Two types OpenEXR reads by their content, not their size: a channel list up to its
        // empty name (a list of another size put the next attribute, one claiming 2 GB, out of
        // step with this check), and a preview of width x height RGBA pixels (allocated first).
        const auto outOfStep = [&](uint64_t content) {
            return "corrupt OpenEXR header: attribute '" + name + "' of type " + type + " has " +
                   std::to_string(size) + " bytes, its content " + std::to_string(content);
        };
        if (type == "chlist") {
            uint64_t content = 0;
            std::string channel;
            while (content < uint64_t(size)) {
                if (!readName(channel))
                    return outOfStep(uint64_t(f.tellg()) - at);
                content += channel.size() + 1;
                if (channel.empty())
                    break;
                content += 16; // pixel type, pLinear and reserved, x and y sampling
                f.seekg(16, std::ios::cur);
            }
            if (!channel.empty() || content != uint64_t(size))
                return outOfStep(content);
        } else if (type == "preview") {
            uint8_t wh[8];
            if (size < 8 || !f.read(reinterpret_cast<char*>(wh), 8))
                return outOfStep(8);
            auto u32 = [&](int i) {
                return uint64_t(wh[i]) | uint64_t(wh[i + 1]) << 8 | uint64_t(wh[i + 2]) << 16 |
                       uint64_t(wh[i + 3]) << 24;
            };
            const uint64_t content = 8 + 4 * u32(0) * u32(4);
            if (content != uint64_t(size))
                return outOfStep(content);
        }
        f.clear();
        f.seekg(std::streamoff(at + uint64_t(size)), std::ios::beg);
    }
}

// Writes `pixels` (spec's size and channels, as `type`) to `file` and reads it back: OpenImageIO
// does not report every failed write (a PNG or EXR that may not grow past a limit closes "fine",
// truncated), so a file that does not read back whole is a failure too.
void writeImageWhole(const std::string& file, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                     const void* pixels, const std::function<void(const std::string&)>& fail) {
    auto out = OIIO::ImageOutput::create(file);
    if (!out)
        fail(firstLine(OIIO::geterror()));
    if (!out->open(file, spec) || !out->write_image(type, pixels) || !out->close())
        fail(firstLine(out->geterror()));
    auto in = OIIO::ImageInput::open(file);
    std::vector<uint8_t> back(spec.image_pixels() * size_t(spec.nchannels) * type.size());
    if (!in || !in->read_image(0, 0, 0, spec.nchannels, type, back.data()) || in->has_error())
        fail("the file written does not read back whole (is the disk full?)");
    in->close();
}

} // namespace

void checkDbiExrPath(const std::string& path) {
    if (!hasExtension(path, {".exr"}))
        throw Error("cannot write DBI '" + path + "': a DBI file must end in .exr");
}

void writeDbiExr(const std::string& path, const Dbi& image) {
    writeDbiExr(path, image, image.bounds(), image.width(), image.height());
}

void writeDbiExr(const std::string& path, const Dbi& image, const PixelRect& rectInFrame,
                 int frameWidth, int frameHeight) {
    checkDbiExrPath(path);
    if (image.empty() || rectInFrame.w != image.width() || rectInFrame.h != image.height() ||
        !PixelRect{0, 0, frameWidth, frameHeight}.contains(rectInFrame))
        throw Error("cannot write DBI '" + path + "': the image does not fit its frame");

    OIIO::ImageSpec spec(image.width(), image.height(), 5, OIIO::TypeDesc::HALF);
    spec.channelnames = {"R", "G", "B", "A", "Z"};
    spec.channelformats = {OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF,
                           OIIO::TypeDesc::HALF, OIIO::TypeDesc::FLOAT};
    spec.alpha_channel = 3;
    spec.z_channel = 4;
    // Data window: the rectangle, counted from the top of the frame; display window: the frame.
    spec.x = rectInFrame.x;
    spec.y = frameHeight - (rectInFrame.y + rectInFrame.h);
    spec.full_x = 0;
    spec.full_y = 0;
    spec.full_width = frameWidth;
    spec.full_height = frameHeight;
    spec.attribute("compression", "zip");
    spec.attribute("Software", "trephine render");

    std::vector<float> pixels(size_t(image.width()) * image.height() * 5);
    for (int row = 0; row < image.height(); ++row) {
        int y = image.height() - 1 - row; // file rows run top-down
        for (int x = 0; x < image.width(); ++x) {
            float* out = &pixels[(size_t(row) * image.width() + x) * 5];
            const uint8_t* c = image.color(x, y);
            for (int i = 0; i < 4; ++i)
                out[i] = float(c[i]) / 255.0f;
            out[4] = image.depth(x, y);
        }
    }
    // Through a temporary file: a write that fails (a full disk) leaves an earlier file whole.
    auto fail = [&](const std::string& why) {
        throw Error("cannot write DBI '" + path + "': " + why);
    };
    replaceVia(
        path,
        [&](const std::string& file) {
            writeImageWhole(file, spec, OIIO::TypeDesc::FLOAT, pixels.data(), fail);
        },
        fail);
}

DbiFile readDbiExr(const std::string& path) {
    if (!std::filesystem::exists(path))
        throw Error("cannot read DBI '" + path + "': no such file");
    if (const std::string problem = exrHeaderProblem(path); !problem.empty())
        throw Error("cannot read DBI '" + path + "': " + problem);
    auto in = OIIO::ImageInput::open(path);
    if (!in)
        throw Error("cannot read DBI '" + path + "': " + firstLine(OIIO::geterror()));
    if (std::string(in->format_name()) != "openexr")
        throw Error("cannot read DBI '" + path + "': it is a " + in->format_name() +
                    " file, not OpenEXR (a DBI is an EXR with R, G, B and Z channels)");
    const OIIO::ImageSpec& spec = in->spec();
    auto channel = [&](const char* name) {
        auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
        return it == spec.channelnames.end() ? -1 : int(it - spec.channelnames.begin());
    };
    int ch[5] = {channel("R"), channel("G"), channel("B"), channel("A"), channel("Z")};
    if (ch[4] < 0)
        throw Error("cannot read DBI '" + path +
                    "': it has no Z channel, so it is not a depth-buffered image");
    if (ch[0] < 0 || ch[1] < 0 || ch[2] < 0)
        throw Error("cannot read DBI '" + path + "': it lacks an R, G or B channel");
    if (spec.depth > 1 || spec.width <= 0 || spec.height <= 0)
        throw Error("cannot read DBI '" + path + "': not a 2D image");

    const int w = spec.width, h = spec.height, nc = spec.nchannels;
    std::vector<float> pixels(size_t(w) * h * nc);
    if (!in->read_image(0, 0, 0, nc, OIIO::TypeDesc::FLOAT, pixels.data()))
        throw Error("cannot read DBI '" + path + "': " + firstLine(in->geterror()));

    DbiFile file;
    file.frameWidth = spec.full_width;
    file.frameHeight = spec.full_height;
    int yTop = spec.y - spec.full_y;
    file.rectInFrame = {spec.x - spec.full_x, spec.full_height - (yTop + h), w, h};
    file.image = Dbi(w, h);
    auto to8 = [](float v) { return uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); };
    for (int row = 0; row < h; ++row) {
        int y = h - 1 - row;
        for (int x = 0; x < w; ++x) {
            const float* p = &pixels[(size_t(row) * w + x) * nc];
            float z = p[ch[4]];
            uint8_t* c = file.image.color(x, y);
            c[0] = to8(p[ch[0]]), c[1] = to8(p[ch[1]]), c[2] = to8(p[ch[2]]);
            c[3] = ch[3] >= 0 ? to8(p[ch[3]]) : (z < kBackgroundDepth ? 255 : 0);
            file.image.depth()[file.image.index(x, y)] = z;
        }
    }
    return file;
}

void checkColorPngPath(const std::string& path) {
    if (!hasExtension(path, {".png"}))
        throw Error("cannot write '" + path + "': a colour image must end in .png");
}

void writeColorPng(const std::string& path, const Dbi& image) {
    checkColorPngPath(path);
    if (image.empty())
        throw Error("cannot write '" + path + "': the image is empty");
    std::vector<uint8_t> rgb(size_t(image.width()) * image.height() * 3);
    for (int row = 0; row < image.height(); ++row) {
        int y = image.height() - 1 - row;
        for (int x = 0; x < image.width(); ++x)
            std::copy_n(image.color(x, y), 3, &rgb[(size_t(row) * image.width() + x) * 3]);
    }
    OIIO::ImageSpec spec(image.width(), image.height(), 3, OIIO::TypeDesc::UINT8);
    auto fail = [&](const std::string& why) { throw Error("cannot write '" + path + "': " + why); };
    replaceVia(
        path,
        [&](const std::string& file) {
            writeImageWhole(file, spec, OIIO::TypeDesc::UINT8, rgb.data(), fail);
        },
        fail);
}

} // namespace trephine
