// The CPU ray caster, counting the pixels it is asked to render into a shared counter: a test
// reads what a step rendered, or uses the count as a work clock (1 us a pixel) so the pieces
// charged to peers cost the same on every machine.
#pragma once

#include "libsim/dbi_renderer.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace trephine::testing {

class CountingRenderer final : public DbiRenderer {
public:
    CountingRenderer(const Volume& v, ThreadPool* pool, std::shared_ptr<uint64_t> pixels)
        : m_cpu(v, pool), m_pixels(std::move(pixels)) {}
    void volumeChanged(const Box3i& changed) override { m_cpu.volumeChanged(changed); }
    void rebuild() override { m_cpu.rebuild(); }
    void render(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache) override {
        *m_pixels += uint64_t(intersect(rect, frame.bounds()).area());
        m_cpu.render(camera, rect, frame, cache);
    }
    // Stops part-way as the CPU ray caster does; counts the columns it rendered.
    int renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame, HitCache* cache,
                   const std::function<bool()>& stop, int atLeast) override {
        const int w = m_cpu.renderBulk(camera, rect, frame, cache, stop, atLeast);
        *m_pixels += uint64_t(w) * uint64_t(rect.h); // the step's rects lie in the frame
        return w;
    }
    Dbi render(const Camera& camera) override { return m_cpu.render(camera); }
    std::string describe() const override { return "CPU, counting pixels"; }

private:
    CpuDbiRenderer m_cpu;
    std::shared_ptr<uint64_t> m_pixels;
};

} // namespace trephine::testing
