// `trephine volume info|convert`: inspect a volume spec and convert between formats. Loading and
// saving live in libsim (volume_io.h) and sim_image (volume_slices.h); this is only wiring.
#include "modes.h"

#include "libsim/error.h"
#include "libsim/volume_io.h"
#include "libsim_image/volume_slices.h"

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

namespace trephine::app {

namespace {

struct VolumeOptions {
    std::string spec;
    std::string out;
    std::string dims;
    std::string spacing;
    std::string type;
    std::string endian;
    bool uncompressed = false;
};

void addSpecOptions(CLI::App* sub, VolumeOptions& o) {
    sub->add_option("SPEC", o.spec, "Volume spec: skull:N, sphere:N, box:N, a file, a folder...")
        ->required();
    sub->add_option("--dims", o.dims, "X,Y,Z: read SPEC as a headerless raw file of these sizes");
    sub->add_option("--type", o.type,
                    "Scalar type of a raw file: uint8 (default), int8, int16, uint16, int32, "
                    "uint32, float32, float64");
    sub->add_option("--endian", o.endian, "Byte order of a raw file: little (default) or big");
    sub->add_option("--spacing", o.spacing, "a,b,c: voxel spacing in mm (overrides the file's)");
}

// SPEC plus --dims/--type/--endian becomes a raw: spec; --spacing overrides any volume's spacing.
Volume openWithOptions(const VolumeOptions& o) {
    std::string spec = o.spec;
    if (!o.dims.empty()) {
        if (spec.rfind("raw:", 0) == 0)
            throw Error("--dims: SPEC is already a raw: spec; give dims=X,Y,Z in it or drop raw:");
        spec = "raw:" + spec + "?dims=" + o.dims;
        if (!o.type.empty())
            spec += "&type=" + o.type;
        if (!o.endian.empty())
            spec += "&endian=" + o.endian;
    } else if (!o.type.empty() || !o.endian.empty()) {
        throw Error(std::string(o.type.empty() ? "--endian" : "--type") +
                    ": only for headerless raw files, which also need --dims X,Y,Z");
    }
    Volume v = openVolume(spec);
    if (!o.spacing.empty()) {
        VolumeSpecQuery q;
        q.options.emplace_back("spacing", o.spacing);
        v.setSpacing(parseSpacingOption(q, "--spacing", v.spacing()));
    }
    return v;
}

void printInfo(const std::string& spec, const Volume& v) {
    const glm::ivec3 d = v.dims();
    const glm::vec3 s = v.spacing();
    const glm::vec3 e = v.extentMm();
    std::printf("volume:      %s\n", spec.c_str());
    std::printf("dimensions:  %d x %d x %d voxels\n", d.x, d.y, d.z);
    std::printf("spacing:     %g x %g x %g mm\n", s.x, s.y, s.z);
    std::printf("extent:      %g x %g x %g mm\n", e.x, e.y, e.z);
    std::printf("bytes:       %zu (%zu voxels, 1 byte density + 1 byte material each)\n",
                2 * v.voxelCount(), v.voxelCount());
    std::printf("materials:\n");
    const std::vector<int64_t> counts = v.materialCounts();
    for (int m = 0; m < kMaterialCount; ++m) {
        const std::string name(materialName(Material(m)));
        std::printf("  %-10s %12lld  %6.2f %%\n", name.c_str(), static_cast<long long>(counts[m]),
                    100.0 * double(counts[m]) / double(v.voxelCount()));
    }
}

} // namespace

void addVolumeMode(CLI::App& root, int& exitCode) {
    CLI::App* volume = root.add_subcommand("volume", "Inspect and convert volumes");
    volume->require_subcommand(1);
    volume->footer(volumeSpecHelp());

    auto infoOptions = std::make_shared<VolumeOptions>();
    CLI::App* info = volume->add_subcommand(
        "info", "Print dimensions, spacing (mm), extent, bytes and voxels per material");
    addSpecOptions(info, *infoOptions);
    info->footer(volumeSpecHelp());
    info->callback([infoOptions, &exitCode] {
        printInfo(infoOptions->spec, openWithOptions(*infoOptions));
        exitCode = 0;
    });

    auto convertOptions = std::make_shared<VolumeOptions>();
    CLI::App* convert = volume->add_subcommand(
        "convert", "Write a volume as .nrrd/.nhdr (density + materials), .nii/.nii.gz (density) "
                   "or slices:FOLDER (8-bit PNG slices)");
    addSpecOptions(convert, *convertOptions);
    convert
        ->add_option("OUT", convertOptions->out,
                     "Output: OUT.nrrd, OUT.nhdr, OUT.nii[.gz] or slices:FOLDER")
        ->required();
    convert->add_flag("--uncompressed", convertOptions->uncompressed,
                      "Write .nrrd/.nhdr data raw instead of gzip");
    convert->footer(volumeSpecHelp());
    convert->callback([convertOptions, &exitCode] {
        const VolumeOptions& o = *convertOptions;
        // Before the volume is read, and naming the mistake ("slices:" alone names no folder).
        if (o.out == "slices:")
            throw Error("OUT slices:: name the folder for the slices, e.g. slices:out/");
        // And "slices:FILE" said "the folder is not empty" of a file.
        std::error_code ec;
        if (o.out.rfind("slices:", 0) == 0 && std::filesystem::exists(o.out.substr(7), ec) &&
            !std::filesystem::is_directory(o.out.substr(7), ec))
            throw Error("OUT " + o.out + ": " + o.out.substr(7) +
                        " is a file, not a folder: name a new or empty folder for the slices");
        Volume v = openWithOptions(o);
        if (o.out.rfind("slices:", 0) == 0)
            saveVolumeSlices(v, o.out.substr(7));
        else
            saveVolume(v, o.out, SaveOptions{.compress = !o.uncompressed});
        const glm::ivec3 d = v.dims();
        std::printf("wrote %s (%d x %d x %d voxels)\n", o.out.c_str(), d.x, d.y, d.z);
        exitCode = 0;
    });
}

} // namespace trephine::app
