#include "libsim/dbi_renderer.h"

#include "libsim/thread_pool.h"

namespace trephine {

CpuDbiRenderer::CpuDbiRenderer(const Volume& volume, ThreadPool* pool)
    : m_renderer(volume, pool), m_threads(pool ? pool->size() : 1) {}

std::string CpuDbiRenderer::describe() const {
    return "CPU, " + std::to_string(m_threads) + (m_threads == 1 ? " thread" : " threads");
}

} // namespace trephine
