#include "libsim_gpu/gpu_renderer.h"

#include "libsim_gpu/volume_raycaster.h"

#include "libsim/error.h"

#include <cassert>

namespace trephine::gpu {

GpuRenderer::GpuRenderer(const Volume& volume, std::shared_ptr<EglContext> context)
    : m_volume(&volume), m_context(std::move(context)) {
    EglContext::Current current(*m_context);
    // The same ray either way (docs/rendering.md): a compute dispatch where the driver has 4.3,
    // fragments through a framebuffer where it has 3.3 only.
    m_caster = std::make_unique<VolumeRaycaster>(m_context->info().compute
                                                     ? VolumeRaycaster::Pipeline::Compute
                                                     : VolumeRaycaster::Pipeline::Fragment);
    try {
        m_caster->upload(volume);
    } catch (...) {
        m_caster.reset(); // the textures made so far go while the context is current
        throw;
    }
}

// A renderer that failed may have lost its context: then its GL objects are left to the driver
// rather than a throw ending the process.
GpuRenderer::~GpuRenderer() {
    try {
        EglContext::Current current(*m_context);
        m_caster.reset(); // its GL objects go while the context is current
    } catch (...) {
        (void)m_caster.release();
    }
}

void GpuRenderer::volumeChanged(const Box3i& changed) {
    EglContext::Current current(*m_context);
    m_caster->updateBox(*m_volume, changed);
}

void GpuRenderer::rebuild() {
    EglContext::Current current(*m_context);
    m_caster->upload(*m_volume);
}

void GpuRenderer::render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache*) {
    assert(frame.width() == camera.width && frame.height() == camera.height &&
           "GpuRenderer::render: the frame is not the camera's size");
    EglContext::Current current(*m_context);
    m_caster->render(camera, rect);
    m_caster->readBack(frame);
}

Dbi GpuRenderer::render(const Camera& camera) {
    Dbi frame(camera.width, camera.height);
    render(camera, frame.bounds(), frame, nullptr);
    return frame;
}

std::string GpuRenderer::describe() const {
    return "GPU: " + m_context->info().renderer +
           (m_caster->pipeline() == VolumeRaycaster::Pipeline::Compute
                ? ""
                : " (fragment shaders: no OpenGL 4.3)");
}

RendererChoice parseRendererChoice(const std::string& name) {
    if (name == "cpu")
        return RendererChoice::Cpu;
    if (name == "gpu")
        return RendererChoice::Gpu;
    if (name == "auto")
        return RendererChoice::Auto;
    throw Error("--renderer " + name + ": choose cpu, gpu or auto");
}

std::optional<DbiRendererFactory> chooseRenderer(RendererChoice choice, std::string* why) {
    auto say = [&](std::string line) {
        if (why)
            *why = std::move(line);
    };
    if (choice == RendererChoice::Cpu) {
        say("the CPU (--renderer cpu)");
        return std::nullopt;
    }
    std::string failure;
    std::shared_ptr<EglContext> context = EglContext::shared(&failure);
    if (!context) {
        if (choice == RendererChoice::Gpu)
            throw Error("--renderer gpu: " + failure);
        say("the CPU (--renderer auto: " + failure + ")");
        return std::nullopt;
    }
    if (choice == RendererChoice::Auto && context->info().software) {
        say("the CPU (--renderer auto: OpenGL is " + context->info().renderer +
            ", a software renderer)");
        return std::nullopt;
    }
    say("the GPU: " + context->info().renderer + " (OpenGL " + context->info().version +
        (context->info().compute ? ")" : "; fragment shaders: no 4.3)"));
    return DbiRendererFactory([context](const Volume& volume, ThreadPool*) {
        return std::unique_ptr<DbiRenderer>(new GpuRenderer(volume, context));
    });
}

} // namespace trephine::gpu
