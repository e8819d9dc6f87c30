// The server's DBI renderer on the GPU: the shared ray caster (VolumeRaycaster) in its own EGL
// context with no display. It renders what the CPU Renderer renders within the tolerance
// docs/rendering.md states (eye depth within 0.1 voxel at >= 99 % of pixels, colours within 4
// levels), and any rectangle bit for bit as its full frame. After erosion only the changed box
// is uploaded.
#pragma once

#include "libsim/dbi_renderer.h"
#include "libsim_gpu/egl_context.h"

#include <memory>
#include <optional>

namespace trephine::gpu {

class VolumeRaycaster;

class GpuRenderer final : public DbiRenderer {
public:
    // Uploads `volume` (which must outlive the renderer) into `context`'s textures. Throws
    // trephine::Error when the GL refuses it (too large, out of memory).
    GpuRenderer(const Volume& volume, std::shared_ptr<EglContext> context);
    ~GpuRenderer() override;

    void volumeChanged(const Box3i& changed) override;
    void rebuild() override;
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache*) override;
    Dbi render(const Camera& camera) override;
    std::string describe() const override;

private:
    const Volume* m_volume;
    std::shared_ptr<EglContext> m_context;
    std::unique_ptr<VolumeRaycaster> m_caster; // used only while the context is current
};

enum class RendererChoice { Cpu, Gpu, Auto };

// Parses "cpu", "gpu" or "auto"; throws trephine::Error naming the choices otherwise.
RendererChoice parseRendererChoice(const std::string& name);

// What `--renderer` picks: nullopt for the CPU renderer, else a factory of GPU renderers on one
// EGL context. Gpu takes any GL, llvmpipe included, and throws trephine::Error when there is
// none; Auto takes a hardware renderer only, else the CPU. `why` (may be null) gets one line
// saying what was chosen and why.
std::optional<DbiRendererFactory> chooseRenderer(RendererChoice choice, std::string* why);

} // namespace trephine::gpu
