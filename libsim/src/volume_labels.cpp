// Label maps: a segmentation beside a scan names the critical structures a CT cannot show (dura,
// the sinus, the meningeal artery), the way 3D Slicer keeps them: an integer volume of the scan's
// dimensions whose values are segments, and a table naming each. docs/volumes.md "Label maps".
#include "libsim/skull.h"
#include "volume_io_detail.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <fstream>
#include <sstream>

namespace trephine::detail {

namespace {

std::string lower(std::string s) {
    for (char& c : s)
        c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// The structure a segment's name means, by the words surgeons and Slicer's templates use; bone
// and anything else keeps the labels the intensities give.
std::optional<Material> structureOfName(const std::string& name) {
    const std::string n = lower(name);
    struct Word {
        const char* word;
        Material material;
    };
    static constexpr std::array<Word, 7> kWords = {{{"sinus", Material::Sinus},
                                                    {"meningeal", Material::Artery},
                                                    {"artery", Material::Artery},
                                                    {"mma", Material::Artery},
                                                    {"dura", Material::Dura},
                                                    {"brain", Material::Brain},
                                                    {"cortex", Material::Brain}}};
    for (const Word& w : kWords)
        if (n.find(w.word) != std::string::npos)
            return w.material;
    return std::nullopt;
}

// A colour table (Slicer's .ctbl / .txt): "VALUE NAME [R G B A]" per line, '#' comments.
std::map<int, std::string> readNamesTable(const std::string& path) {
    std::ifstream in(path);
    if (!in)
        fail(path, "cannot open the label names table");
    std::map<int, std::string> names;
    std::string line;
    int lineNo = 0;
    while (std::getline(in, line)) {
        ++lineNo;
        if (line.size() > 4096)
            fail(path,
                 "line " + std::to_string(lineNo) + " is longer than 4096 bytes: not a table");
        std::istringstream words(line);
        std::string first;
        if (!(words >> first) || first[0] == '#')
            continue;
        int value = 0;
        std::string name;
        try {
            size_t used = 0;
            value = std::stoi(first, &used);
            if (used != first.size())
                throw std::invalid_argument(first);
        } catch (const std::exception&) {
            fail(path, "line " + std::to_string(lineNo) + ": expected 'VALUE NAME', found '" +
                           first + "'");
        }
        if (!(words >> name))
            fail(path, "line " + std::to_string(lineNo) + ": label " + first + " has no name");
        if (value == 0)
            continue; // the background
        if (value < 1 || value > kMaxLabelValue)
            fail(path, "line " + std::to_string(lineNo) + ": label " + first +
                           " is not a label from 1 to " + std::to_string(kMaxLabelValue));
        names[value] = name;
    }
    return names;
}

uint8_t structureDensity(Material m) {
    switch (m) {
    case Material::Sinus:
        return kSkullSinusDensity;
    case Material::Artery:
        return kSkullArteryDensity;
    case Material::Dura:
        return kSkullDuraDensity;
    default:
        return kSkullBrainDensity;
    }
}

} // namespace

void applyLabelMap(Volume& v, const std::string& labelsPath, const std::string& namesPath,
                   const std::string& spec) {
    const std::string labelsName = spec + ": labels " + labelsPath;
    const DensityWindow identity{0.0, 255.0}; // each integer label its own byte
    const Volume labels = readVolumeFile(labelsPath, identity);
    if (labels.dims() != v.dims())
        fail(labelsName, "the label map is " + std::to_string(labels.dims().x) + "x" +
                             std::to_string(labels.dims().y) + "x" +
                             std::to_string(labels.dims().z) + " but the volume is " +
                             std::to_string(v.dims().x) + "x" + std::to_string(v.dims().y) + "x" +
                             std::to_string(v.dims().z));
    const std::map<int, std::string> names =
        namesPath.empty() ? readNrrdSegmentNames(labelsPath) : readNamesTable(namesPath);
    if (names.empty())
        fail(labelsName, "no label names: give a names table (&names=FILE) or a 3D Slicer "
                         "segmentation NRRD with SegmentN_Name fields");
    std::array<std::optional<Material>, 256> of{};
    bool any = false;
    for (const auto& [value, name] : names) {
        of[size_t(value)] = structureOfName(name);
        any |= of[size_t(value)].has_value();
    }
    if (!any)
        fail(labelsName, "no label names a structure Trephine models (names containing sinus, "
                         "artery, meningeal, mma, dura, brain or cortex)");
    const uint8_t* lab = labels.densityData();
    uint8_t* den = v.densityData();
    uint8_t* mat = v.materialData();
    for (size_t i = 0, n = v.voxelCount(); i < n; ++i) {
        if (lab[i] == 0)
            continue;
        if (lab[i] > kMaxLabelValue)
            fail(labelsName, "voxel " + std::to_string(i) + " has a label above " +
                                 std::to_string(kMaxLabelValue));
        if (const std::optional<Material> m = of[lab[i]]) {
            mat[i] = uint8_t(*m);
            // A CT shows soft tissue below the bone threshold: the labelled structure takes the
            // procedural skull's density for it, so exposed dura, sinus and artery are seen.
            den[i] = std::max(den[i], structureDensity(*m));
        }
    }
}

} // namespace trephine::detail
