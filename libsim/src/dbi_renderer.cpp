#include "libsim/dbi_renderer.h"

#include "libsim/thread_pool.h"

#include <exception>
#include <utility>

namespace trephine {

CpuDbiRenderer::CpuDbiRenderer(const Volume& volume, ThreadPool* pool)
    : m_renderer(volume, pool), m_threads(pool ? pool->size() : 1) {}

std::string CpuDbiRenderer::describe() const {
    return "CPU, " + std::to_string(m_threads) + (m_threads == 1 ? " thread" : " threads");
}

FallbackDbiRenderer::FallbackDbiRenderer(const Make& primary, Make fallback, Told onFallback)
    : m_fallback(std::move(fallback)), m_told(std::move(onFallback)) {
    try {
        m_current = primary();
    } catch (const std::exception& e) {
        fallBack("the configured renderer", e.what());
    }
}

void FallbackDbiRenderer::fallBack(const std::string& primary, const std::string& error) {
    std::unique_ptr<DbiRenderer> next = m_fallback(); // should it throw, nothing changed
    next->setBulkPool(m_bulkPool);
    m_fallback = nullptr;
    m_current = std::move(next);
    if (m_told)
        m_told(primary, error, m_current->describe());
}

template <typename F>
auto FallbackDbiRenderer::guarded(F&& f) {
    if (!m_fallback)
        return f(*m_current);
    try {
        return f(*m_current);
    } catch (const std::exception& e) {
        fallBack(m_current->describe(), e.what());
    }
    return f(*m_current);
}

void FallbackDbiRenderer::volumeChanged(const Box3i& changed) {
    guarded([&](DbiRenderer& r) { r.volumeChanged(changed); });
}

void FallbackDbiRenderer::rebuild() {
    guarded([&](DbiRenderer& r) { r.rebuild(); });
}

void FallbackDbiRenderer::render(const Camera& camera, const PixelRect& rect, Dbi& frame,
                                 HitCache* cache) {
    guarded([&](DbiRenderer& r) { r.render(camera, rect, frame, cache); });
}

void FallbackDbiRenderer::renderChanged(const Camera& camera, const PixelRect& rect, Dbi& frame,
                                        HitCache& cache, const Box3i& changed) {
    guarded([&](DbiRenderer& r) { r.renderChanged(camera, rect, frame, cache, changed); });
}

int FallbackDbiRenderer::renderBulk(const Camera& camera, const PixelRect& rect, Dbi& frame,
                                    HitCache* cache, const std::function<bool()>& stop,
                                    int atLeast) {
    return guarded(
        [&](DbiRenderer& r) { return r.renderBulk(camera, rect, frame, cache, stop, atLeast); });
}

void FallbackDbiRenderer::setBulkPool(ThreadPool* pool) {
    m_bulkPool = pool;
    m_current->setBulkPool(pool);
}

Dbi FallbackDbiRenderer::render(const Camera& camera) {
    return guarded([&](DbiRenderer& r) { return r.render(camera); });
}

} // namespace trephine
