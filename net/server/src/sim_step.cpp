#include "net/sim_step.h"

#include "libsim/dbi_preview.h"
#include "libsim/dirty_rect.h"
#include "libsim/tool.h"
#include "net/tool_model.h"
#include "net/view.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <memory>
#include <utility>

namespace trephine::net {

namespace {

// Air has no material: a voxel of density 0 is labelled Air, as erosion and box cuts leave it.
// With that invariant a volume client derives materials exactly from box densities.
Volume normaliseAir(Volume v) {
    uint8_t* den = v.densityData();
    uint8_t* mat = v.materialData();
    for (size_t i = 0; i < v.voxelCount(); ++i)
        if (den[i] == 0)
            mat[i] = uint8_t(Material::Air);
    return v;
}

int64_t pixelsOf(const Dbi& frame) {
    return int64_t(frame.width()) * frame.height();
}

// The configured renderer (the GPU's) with the CPU ray caster behind it should it fail, when it
// is made (a volume too large for it) or later (out of memory, a lost device): the server says so
// once and counts it (`renderer_fallbacks`).
std::unique_ptr<DbiRenderer> makeRenderer(const StepConfig& c, const Volume& v, ThreadPool& pool,
                                          ReportBook& book, bool& replaced) {
    auto cpu = [&v, &pool] { return std::make_unique<CpuDbiRenderer>(v, &pool); };
    if (!c.renderer)
        return cpu();
    auto told = [&book, &replaced](const std::string& primary, const std::string& error,
                                   const std::string& now) {
        std::fprintf(stderr, "trephine server: %s failed (%s); rendering on %s from now on\n",
                     primary.c_str(), error.c_str(), now.c_str());
        book.count(&ServerCounters::rendererFallbacks);
        replaced = true;
    };
    return std::make_unique<FallbackDbiRenderer>([&] { return c.renderer(v, &pool); }, cpu, told);
}

AssessmentConfig withSweep(const StepConfig& c) {
    AssessmentConfig a = c.assessment;
    a.maxSweepMm = c.maxSweepMm;
    return a;
}

} // namespace

SimulationStep::SimulationStep(Volume volume, const StepConfig& config, Outbox& outbox,
                               ReportBook& book, ServerClock clock)
    : m_config(config), m_outbox(outbox), m_book(book), m_clock(std::move(clock)),
      m_volume(normaliseAir(std::move(volume))), m_pool(config.renderThreads, "trephine-cast"),
      m_renderer(makeRenderer(config, m_volume, m_pool, book, m_rendererReplaced)),
      m_assessment(m_volume, withSweep(config), book, &m_pool),
      m_share(config.workClock ? config.workClock : ServerClock(steadyNowUs)) {}

void SimulationStep::Batch::changedBy(const Box3i& box, uint64_t arrivedUs) {
    changed.merge(box);
    causeUs = causeUs ? std::min(causeUs, arrivedUs) : arrivedUs;
}

void SimulationStep::step(std::span<const LogRecord> batch, uint64_t now) {
    Batch b;
    for (const LogRecord& r : batch) {
        // The assessment's time: when the event arrived (the server stamps every event it
        // queues, and the log keeps that time), else the step's. So a replay of the log times
        // joins, leaves and samples as the live server did, whenever each was stepped.
        const uint64_t at = r.timeUs ? r.timeUs : now;
        std::visit(Handlers{
                       [&](const JoinEvent& e) { applyJoin(e, at, b, now); },
                       [&](const ViewEvent& e) { applyView(e, b, now); },
                       [&](const SyncEvent& e) { applySync(e, b, now); },
                       [&](const LeaveEvent& e) { applyLeave(e, at, b); },
                       [&](const CutEvent& e) { applyCut(e, r.timeUs, b); },
                       [&](const VoxelsEvent& e) { applyVoxels(e, r.timeUs, b); },
                       [&](const ToolEvent& e) { applyTool(e, r.timeUs, at, b); },
                       [](const auto&) {}, // the policy's decisions
                   },
                   r.event);
    }
    if (!m_config.publish) {
        // The brick grid takes the change before the next render.
        if (b.materials)
            m_gridRebuildPending = true;
        else
            m_gridPending.merge(b.changed);
        return;
    }
    // Volume clients need none of the rendering below: in a mixed session they never wait for
    // the DBI clients' renders.
    postVolumes(b);
    renderViews(b, updateGrid(b), now);
    m_assessment.tick(now);
    m_book.record([&](ServerReport& r) {
        for (const auto& [id, c] : m_clients)
            r.peers[id].chargedUs = m_share.charged(id);
    });
}

// [SECTION] events

void SimulationStep::applyJoin(const JoinEvent& ev, uint64_t at, Batch& b, uint64_t now) {
    Client& c = m_clients[ev.client];
    c.camera = toCamera(ev.view);
    for (ViewFrame& v : m_views) // kept by a peer gone whose id this one reuses: not its to spend
        if (v.kept && v.keptBy == ev.client)
            v.keptBy = 0;
    m_assessment.join(ev.client, ev.name, ev.role, at);
    c.sync = ev.sync;
    m_outbox.join(ev.client, ev.inFlight, ev.codec, ev.volumeCodec);
    if (c.sync == Sync::Volume)
        b.needVolume[ev.client] = now;
    else
        b.needFull[ev.client] = now;
}

void SimulationStep::applyView(const ViewEvent& ev, Batch& b, uint64_t now) {
    Client& c = m_clients[ev.client];
    c.camera = toCamera(ev.view);
    m_outbox.viewChanged(ev.client, ev.viewId);
    // A volume client renders its views itself; the server only keeps the camera for a later
    // switch to DBI. A DBI client's waiting image belonged to the view it left (maybe another
    // size, even under the same id): the full image of the new view replaces it.
    if (c.sync == Sync::Dbi)
        b.needFull[ev.client] = now;
}

void SimulationStep::applySync(const SyncEvent& ev, Batch& b, uint64_t now) {
    auto it = m_clients.find(ev.client);
    if (it == m_clients.end())
        return;
    it->second.sync = ev.sync;
    m_outbox.modeChanged(ev.client, ev.sync, ev.volumeCodec);
    if (ev.sync == Sync::Volume) {
        b.needFull.erase(ev.client);
        it->second.fullCauseUs = 0;
        b.needVolume[ev.client] = now;
    } else {
        b.needVolume.erase(ev.client);
        b.needFull[ev.client] = now;
    }
}

void SimulationStep::applyLeave(const LeaveEvent& ev, uint64_t at, Batch& b) {
    m_assessment.leave(ev.client, at);
    m_clients.erase(ev.client);
    m_outbox.leave(ev.client);
    m_share.forget(ev.client);
    b.needFull.erase(ev.client);
    b.needVolume.erase(ev.client);
}

void SimulationStep::applyCut(const CutEvent& ev, uint64_t arrivedUs, Batch& b) {
    const Box3i box = ev.box.intersect(m_volume.bounds());
    if (box.empty())
        return;
    const uint64_t e0 = m_clock();
    {
        std::unique_lock write(m_voxelMutex);
        m_volume.fill(box, 0, Material::Air);
    }
    b.erodeUs += m_clock() - e0;
    b.changedBy(box, arrivedUs);
}

void SimulationStep::applyVoxels(const VoxelsEvent& ev, uint64_t arrivedUs, Batch& b) {
    const Box3i& box = ev.box; // checked by SessionServer::submitVoxels
    const uint64_t e0 = m_clock();
    {
        std::unique_lock write(m_voxelMutex);
        size_t i = 0;
        for (int z = box.lo.z; z < box.hi.z; ++z)
            for (int y = box.lo.y; y < box.hi.y; ++y)
                for (int x = box.lo.x; x < box.hi.x; ++x, ++i)
                    m_volume.set(x, y, z, ev.density[i], Material(ev.material[i]));
    }
    b.erodeUs += m_clock() - e0;
    b.changedBy(box, arrivedUs);
    b.materials = true;
}

void SimulationStep::applyTool(const ToolEvent& ev, uint64_t arrivedUs, uint64_t at, Batch& b) {
    auto it = m_clients.find(ev.client);
    if (it == m_clients.end())
        return;
    Client& c = it->second;
    const ToolState& t = ev.tool;
    // Unsequenced: an older state that arrives late is dropped (newest wins).
    if (c.hasTool && int32_t(t.sequence - c.lastSequence) <= 0)
        return;
    const ToolShape shape = shapeOf(t);
    if (!c.driller || c.driller->shape().kind != shape.kind ||
        c.driller->shape().diameterMm != shape.diameterMm) {
        c.driller.emplace(shape);
        c.lastDrilling = false; // another tool: nothing to sweep from
    }
    // The step is the time between the client's own timestamps (time passed in).
    float dt = 0.0f;
    if (c.hasTool && t.clientTimeUs > c.lastClientUs)
        dt = std::min(float(double(t.clientTimeUs - c.lastClientUs) * 1e-6), m_config.maxStepS);
    c.hasTool = true;
    c.lastSequence = t.sequence;
    c.lastClientUs = t.clientTimeUs;
    m_book.count(&ServerCounters::toolStatesApplied);
    const ToolPose pose{t.position, t.orientation};
    const ToolPose from = c.lastPose;
    const bool sweep = c.lastDrilling;
    c.lastPose = pose;
    c.lastDrilling = t.drilling && t.speed > 0.0f;
    AppliedTool applied{ev.client, shape,     pose,       c.lastDrilling,
                        dt,        ev.forceN, t.sequence, arrivedUs};
    if (!t.drilling || t.speed <= 0.0f) {
        // Lifted clear of bone between holes, the perforator's clutch re-engages (this is the
        // volume's only writer: reading it needs no lock).
        c.driller->observe(m_volume, pose);
        m_assessment.apply(applied, at);
        return;
    }
    if (dt <= 0.0f) {
        m_assessment.apply(applied, at);
        return;
    }
    // The cutter moved from the last drilling pose to this one during dt: it sweeps the path (a
    // quarter voxel a sub-step, dt shared out), so a fast stroke cuts a groove rather than dents
    // at the sampled poses. The lock is taken per sub-step so that a haptic answer never waits
    // for more than one.
    const glm::vec3 spacing = m_volume.spacing();
    const float quarterVoxel = 0.25f * std::min({spacing.x, spacing.y, spacing.z});
    const std::vector<ToolPose> path =
        sweep ? sweepPoses(from, pose, quarterVoxel, m_config.maxSweepMm)
              : std::vector<ToolPose>{pose};
    const float stepDt = dt / float(path.size());
    const uint64_t e0 = m_clock();
    Box3i changed;
    for (const ToolPose& p : path) {
        DrillResult r;
        {
            std::unique_lock write(m_voxelMutex);
            r = c.driller->drill(m_volume, p, t.speed, stepDt);
        }
        changed.merge(r.changed);
        for (int m = 0; m < kMaterialCount; ++m) {
            applied.removedBy[size_t(m)] += r.removedBy[size_t(m)];
            applied.contactBy[size_t(m)] += r.contactBy[size_t(m)];
        }
    }
    b.erodeUs += m_clock() - e0;
    if (!changed.empty())
        b.changedBy(changed, arrivedUs);
    m_assessment.apply(applied, at);
}

// [SECTION] posting

void SimulationStep::postVolumes(const Batch& b) {
    // The changed voxels themselves, or the whole volume after a join or a switch (which already
    // holds this batch's change).
    for (auto& [id, c] : m_clients) {
        if (c.sync != Sync::Volume)
            continue;
        const uint64_t t0 = m_share.now();
        auto full = b.needVolume.find(id);
        if (full != b.needVolume.end())
            m_outbox.offerVolume(id, m_volume,
                                 VolumeChange{m_volume.bounds(), true, true, full->second, 0});
        else if (!b.changed.empty())
            m_outbox.offerVolume(
                id, m_volume,
                VolumeChange{b.changed, false, b.materials, b.causeUs, uint32_t(b.erodeUs)});
        else
            m_outbox.offerVolume(id, m_volume, std::nullopt);
        m_share.charge(id, m_share.now() - t0); // a design switch's whole volume, mostly
    }
}

void SimulationStep::syncGrid() {
    if (m_gridRebuildPending)
        m_renderer->rebuild(); // voxels written wholesale may have raised densities
    else if (!m_gridPending.empty())
        m_renderer->volumeChanged(m_gridPending); // erosion only: the hit caches stay valid
    m_gridRebuildPending = false;
    m_gridPending = {};
}

// Returns the microseconds the brick grid took (rendering data: it counts in the render stage).
uint32_t SimulationStep::updateGrid(const Batch& b) {
    // Erosion only lowers densities, so the views' hit caches stay valid; voxels written
    // wholesale may raise them, which invalidates every cache (the next render restarts it).
    // With no DBI client the grid waits: nothing here renders.
    if (b.materials)
        m_gridRebuildPending = true;
    else
        m_gridPending.merge(b.changed);
    if (std::none_of(m_clients.begin(), m_clients.end(),
                     [](const auto& c) { return c.second.sync == Sync::Dbi; }))
        return 0;
    const uint64_t g0 = m_clock();
    syncGrid();
    return uint32_t(m_clock() - g0);
}

// Views no DBI client holds any more are kept, whole, for a client that asks for one again
// (StepConfig::keepViewUs); past their time or the kept pixels, or never whole (a view left half
// rendered), they are dropped. Kept views beyond keptPixels go oldest first from the peer keeping
// the most, so a peer changing views every frame spends its own kept views, not others'; each
// counts at least a floor, so tiny views cannot pile up in numbers every step walks.
void SimulationStep::keepOrDrop(std::vector<ViewFrame>& dropped, uint64_t now) {
    const bool keeping = m_config.keepViewUs > 0 && m_config.keptPixels > 0;
    std::erase_if(m_views, [&](ViewFrame& v) {
        const bool held = std::any_of(m_clients.begin(), m_clients.end(),
                                      [&](const auto& c) { return c.second.views(v.camera); });
        if (held && v.kept) { // taken up again
            v.kept = false;
            m_book.count(&ServerCounters::viewsReused);
        }
        if (held)
            return false;
        if (!v.kept && keeping && v.whole() && !v.copying() && !v.previewing()) {
            v.kept = true;
            v.keptUs = now;
            v.keptOrder = ++m_keptViews;
            v.keptBy = v.holders.empty() ? 0 : v.holders.front();
            v.holders.clear();
            v.fresh = {}; // whoever takes it up again gets it whole
            return false;
        }
        if (v.kept && now - v.keptUs < m_config.keepViewUs)
            return false;
        dropped.push_back(std::move(v));
        return true;
    });
    auto weight = [](const ViewFrame& v) {
        return std::max(pixelsOf(v.frame), StepConfig::kKeptViewFloorPixels);
    };
    std::map<uint16_t, int64_t> keptBy;
    int64_t kept = 0;
    for (const ViewFrame& v : m_views)
        if (v.kept) {
            keptBy[v.keptBy] += weight(v);
            kept += weight(v);
        }
    while (kept > m_config.keptPixels && !keptBy.empty()) {
        const uint16_t peer = std::max_element(keptBy.begin(), keptBy.end(), [](auto& x, auto& y) {
                                  return x.second < y.second;
                              })->first;
        auto oldest = m_views.end();
        for (auto v = m_views.begin(); v != m_views.end(); ++v)
            if (v->kept && v->keptBy == peer &&
                (oldest == m_views.end() || v->keptOrder < oldest->keptOrder))
                oldest = v;
        kept -= weight(*oldest);
        if ((keptBy[peer] -= weight(*oldest)) <= 0)
            keptBy.erase(peer);
        dropped.push_back(std::move(*oldest));
        m_views.erase(oldest);
    }
}

void SimulationStep::renderViews(const Batch& b, uint32_t gridUs, uint64_t now) {
    // New views render in slices below, into a dropped frame of their size if there is one: a
    // fresh 2048 x 2048 frame costs ~20 ms of page faults as its rows render, and its rows are
    // all rendered before any pixel of it is sent.
    std::vector<ViewFrame> dropped;
    keepOrDrop(dropped, now);
    for (const auto& [id, cause] : b.needFull)
        if (auto c = m_clients.find(id); c != m_clients.end() && !c->second.fullCauseUs)
            c->second.fullCauseUs = std::max<uint64_t>(cause, 1);
    for (const auto& [id, c] : m_clients) {
        if (c.sync != Sync::Dbi || std::any_of(m_views.begin(), m_views.end(),
                                               [&](const auto& v) { return v.camera == c.camera; }))
            continue;
        ViewFrame& v = m_views.emplace_back();
        v.camera = c.camera;
        auto reuse = std::find_if(dropped.begin(), dropped.end(), [&](const ViewFrame& d) {
            return d.frame.width() == c.camera.width && d.frame.height() == c.camera.height;
        });
        if (reuse != dropped.end()) {
            v.frame = std::move(reuse->frame);
            v.cache = std::move(reuse->cache); // restarted for the new camera, its memory kept
            v.preview = std::move(reuse->preview);
            dropped.erase(reuse);
        } else {
            // Rendered whole before any of it is sent, as a reused frame is.
            v.frame = Dbi::unfilled(c.camera.width, c.camera.height);
        }
        if (m_config.previewPixels > 0 && pixelsOf(v.frame) > m_config.previewPixels)
            v.previewRows = 0;
    }
    for (ViewFrame& v : m_views) {
        markChanged(v, b, gridUs);
        v.holders.clear();
        for (const auto& [id, c] : m_clients)
            if (c.views(v.camera))
                v.holders.push_back(id);
    }
    schedule();
    if (std::exchange(m_rendererReplaced, false)) // in this step, or in an inspection before it
        for (ViewFrame& v : m_views)
            restale(v);
    m_rendering = std::any_of(m_views.begin(), m_views.end(),
                              [](const ViewFrame& v) { return !v.kept && !v.settled(); });
    if (!dropped.empty()) // their frames are freed there, as the task goes
        m_freer->post([frames = std::make_shared<std::vector<ViewFrame>>(std::move(dropped))] {});
}

bool SimulationStep::large(const ViewFrame& v) const {
    return pixelsOf(v.frame) > m_config.slicePixels;
}

// A full image the outbox codes apart is copied for it in chunks, so the step stops for one
// chunk's copy at a time (a whole 512 x 512 frame is 2 MB).
bool SimulationStep::copiedApart(const ViewFrame& v) const {
    return large(v) || m_outbox.codesApart(pixelsOf(v.frame));
}

// The batch's change in the rows rendered so far joins the view's stale pixels; a band of new
// rows it reaches starts again.
void SimulationStep::markChanged(ViewFrame& v, const Batch& b, uint32_t gridUs) {
    if (b.changed.empty() || (v.rowsDone == 0 && v.colsDone == 0))
        return;
    const PixelRect dirty = dirtyScreenRect(v.camera, m_volume, b.changed);
    const int width = v.frame.width();
    if (v.colsDone > 0 && !intersect(dirty, {0, v.rowsDone, v.colsDone, v.bandRows}).empty())
        v.colsDone = 0;
    const PixelRect rect = intersect(dirty, {0, 0, width, v.rowsDone});
    if (rect.empty())
        return;
    v.stale = unite(v.stale, rect);
    v.staleBox.merge(b.changed);
    v.causeUs = v.causeUs ? std::min(v.causeUs, b.causeUs) : b.causeUs;
    v.timing.erodeUs += uint32_t(b.erodeUs);
    v.timing.gridUs += gridUs;
    v.timing.renderUs += gridUs; // the brick grid counts in the render stage
}

// Every pixel rendered so far is to be rendered again (by another renderer), and sent: the rows
// done become stale, a band under way starts again.
void SimulationStep::restale(ViewFrame& v) {
    v.colsDone = 0;
    if (v.rowsDone == 0)
        return;
    v.stale = unite(v.stale, {0, 0, v.frame.width(), std::min(v.rowsDone, v.frame.height())});
    v.staleAll = true;
    v.causeUs = v.causeUs ? v.causeUs : std::max<uint64_t>(m_clock(), 1);
}

// The views' work a piece at a time, the peer whose turn it is first (FairShare), each piece
// charged to the view's clients: whole views' changes (and copies of frames for full images)
// before new views' rows, at most a slice of new rows a step. After any piece, the step stops if
// events wait: they are applied first, so nobody's update waits behind more than one piece of
// another's work, and a peer that asks for more than its share falls behind in its own queue.
void SimulationStep::schedule() {
    m_posted.clear();
    for (ViewFrame& v : m_views)
        if (v.settled() && postView(v)) // a newcomer to a view already whole gets it now
            m_posted.push_back(v.holders.front());
    int64_t rowsLeft = std::max<int64_t>(m_config.slicePixels, 1);
    const int64_t slice = rowsLeft;
    std::vector<ViewFrame*> ready;
    std::vector<uint16_t> peers;
    // One piece for the peer whose turn it is among the views `wanted` selects.
    auto pieceFor = [&](auto wanted, int64_t atLeast) {
        ready.clear();
        for (ViewFrame& v : m_views)
            if (!v.holders.empty() && wanted(v))
                ready.push_back(&v);
        if (ready.empty())
            return false;
        // Ties go to the smaller view: a trainee's rectangle before a larger view's piece.
        std::stable_sort(ready.begin(), ready.end(), [](const ViewFrame* x, const ViewFrame* y) {
            return pixelsOf(x->frame) < pixelsOf(y->frame);
        });
        peers.clear();
        for (const ViewFrame* v : ready)
            peers.push_back(v->holders.front());
        const size_t picked = m_share.pick(peers);
        ViewFrame& v = *ready[picked];
        letSend(v, peers[picked]);
        const uint64_t t0 = m_share.now();
        workOn(v, rowsLeft, atLeast);
        m_share.charge(v.holders, m_share.now() - t0);
        if (v.settled() && postView(v))
            m_posted.push_back(peers[picked]);
        return true;
    };
    auto changed = [](const ViewFrame& v) { return v.whole() && !v.settled(); };
    auto newRows = [](const ViewFrame& v) { return !v.whole(); };
    for (;;) {
        if (!pieceFor(changed, 0) && !(rowsLeft > 0 && pieceFor(newRows, 0)))
            return;
        if (m_config.yield && m_config.yield()) {
            // Events wait and go first, but a step gives new views a chunk's worth of rows:
            // others' changes, each step anew, never starve a newcomer's first picture.
            if (const int64_t given = slice - rowsLeft; given < m_config.chunkPixels)
                pieceFor(newRows, m_config.chunkPixels - given);
            return;
        }
    }
}

// A piece of chunked work (new rows, a frame's copy, a chunk of a large view's change) for a peer
// other than those given an update in the step waits until their updates have been taken: on two
// cores it would take half the CPU their send needs. A view of at most a slice changes in one
// short piece, so a classroom's views do not wait for each other.
void SimulationStep::letSend(const ViewFrame& v, uint16_t peer) {
    const bool chunked = large(v) || !v.whole() || v.copying();
    if (m_config.letSend && chunked && !m_posted.empty() &&
        std::find(m_posted.begin(), m_posted.end(), peer) == m_posted.end()) {
        m_config.letSend();
        m_posted.clear();
    }
}

// One piece of the view's work: the next chunk of its frame's copy, else its next rows (counted
// against the step's `rowsLeft`; a new large view's preview rows first), else its changed
// pixels. Rows before changes: a change in the rows done so far, every step, would otherwise hold
// a new view's rows back for good; nothing exact of it is sent before it is whole, so its changes
// are rendered then, before its copy. New rows give way to waiting events after `atLeast` pixels.
void SimulationStep::workOn(ViewFrame& v, int64_t& rowsLeft, int64_t atLeast) {
    if (v.copying()) {
        copyChunk(v);
        return;
    }
    if (!v.stale.empty() && v.whole()) {
        renderStale(v);
        return;
    }
    if (v.previewing()) {
        previewChunk(v, rowsLeft, atLeast);
        return;
    }
    rowsLeft -= bandPiece(v.camera, v.frame, &v.cache, v.rowsDone, v.colsDone, v.bandRows, rowsLeft,
                          atLeast);
    if (v.whole())
        m_book.count(&ServerCounters::renders);
}

// Renders on from column `cols` of the band of `band` rows from `rows` (a new band: a chunk's
// worth of rows, within the step's `rowsLeft` and the frame), stopping at the next column of
// tiles once events wait (after `atLeast` pixels); a band done moves `rows` on. Returns the pixels
// rendered. A new view's rows are bulk work: another peer's update waits for one tile of them,
// not the band.
int64_t SimulationStep::bandPiece(const Camera& camera, Dbi& frame, HitCache* cache, int& rows,
                                  int& cols, int& band, int64_t rowsLeft, int64_t atLeast) {
    const int width = std::max(frame.width(), 1);
    if (cols == 0)
        band = int(std::clamp<int64_t>(std::min(rowsLeft, m_config.chunkPixels) / width, 1,
                                       frame.height() - rows));
    const PixelRect rect{cols, rows, width - cols, band};
    const int done = m_config.yield ? m_renderer->renderBulk(camera, rect, frame, cache,
                                                             m_config.yield, int(atLeast))
                                    : (m_renderer->render(camera, rect, frame, cache), rect.w);
    cols += done;
    if (cols >= width) {
        cols = 0;
        rows += band;
    }
    return int64_t(done) * band;
}

// The next piece of a new view's preview, counted against `rowsLeft` like its exact rows; the
// last sends it.
void SimulationStep::previewChunk(ViewFrame& v, int64_t& rowsLeft, int64_t atLeast) {
    const Camera half = previewCamera(v.camera);
    if (v.previewRows == 0 && v.previewCols == 0 &&
        (v.preview.width() != half.width || v.preview.height() != half.height))
        v.preview = Dbi::unfilled(half.width, half.height);
    rowsLeft -= bandPiece(half, v.preview, nullptr, v.previewRows, v.previewCols, v.previewBand,
                          rowsLeft, atLeast);
    if (v.previewRows >= half.height)
        postPreview(v);
}

// Every client waiting for the view's full image gets the half-size preview as one (coded apart,
// as large full images are; the client shows each pixel as a 2 x 2 block). They still wait: the
// exact frame's full image follows and replaces it, in the outbox too if the preview has not
// left; a view changed meanwhile drops both, as ever. It goes from a copy made in chunks, as a
// large frame's: the view's own is kept for its next new view of this size.
void SimulationStep::postPreview(ViewFrame& v) {
    v.previewRows = -1;
    if (std::none_of(v.holders.begin(), v.holders.end(),
                     [&](uint16_t id) { return m_clients.at(id).fullCauseUs != 0; }))
        return;
    v.copy = m_outbox.buffer(v.preview.width(), v.preview.height());
    v.rowsCopied = 0;
    v.copyingPreview = true;
}

// The view's changed pixels: all of them for a view of at most a slice (or the whole view, the
// paper's way), else the next chunk of rows of them.
void SimulationStep::renderStale(ViewFrame& v) {
    if (m_fullRender.load() && v.whole()) {
        // The paper's way re-renders the whole view, through the view's hit cache as the volume
        // client's re-render does, so the study compares like with like; BB_screen is sent.
        const uint64_t r0 = m_clock();
        m_renderer->render(v.camera, v.frame.bounds(), v.frame, &v.cache);
        v.timing.renderUs += uint32_t(m_clock() - r0);
        v.fresh = unite(v.fresh, v.stale);
        v.staleRendered();
        m_book.count(&ServerCounters::renders);
        return;
    }
    const int rows =
        large(v)
            ? int(std::clamp<int64_t>(m_config.chunkPixels / std::max(v.stale.w, 1), 1, v.stale.h))
            : v.stale.h;
    const PixelRect chunk{v.stale.x, v.stale.y, v.stale.w, rows};
    const uint64_t r0 = m_clock();
    const int64_t kept = v.cache.kept();
    if (v.staleAll)
        m_renderer->render(v.camera, chunk, v.frame, &v.cache);
    else
        m_renderer->renderChanged(v.camera, chunk, v.frame, v.cache, v.staleBox);
    v.timing.renderUs += uint32_t(m_clock() - r0);
    if (v.cache.kept() > kept)
        m_book.count(&ServerCounters::pixelsKept, uint64_t(v.cache.kept() - kept));
    v.fresh = unite(v.fresh, chunk);
    v.stale.y += rows;
    v.stale.h -= rows;
    if (v.stale.h <= 0) {
        v.staleRendered();
        m_book.count(&ServerCounters::renders);
    }
}

// The pixels rendered since the view's last update to its clients, and the whole frame to those
// waiting for one, each client charged for its update's coding. A view larger than a slice
// starts a copy of its frame for them instead: copying 33 MB at once stopped the step for ~11 ms
// (2048 x 2048 on the 2-core VM).
bool SimulationStep::postView(ViewFrame& v) {
    bool posted = false;
    for (uint16_t id : v.holders) {
        const bool othersFollow = id != v.holders.back();
        Client& c = m_clients.at(id);
        const uint64_t t0 = m_share.now();
        if (c.fullCauseUs && copiedApart(v)) {
            if (!v.copying()) {
                v.copy = m_outbox.buffer(v.frame.width(), v.frame.height());
                v.rowsCopied = 0;
            }
        } else if (c.fullCauseUs) {
            m_outbox.postImage(id, v.camera, v.frame, v.frame.bounds(), true, c.fullCauseUs, {},
                               othersFollow);
            c.fullCauseUs = 0;
            posted = true;
        } else if (!v.fresh.empty()) {
            m_outbox.postImage(id, v.camera, v.frame, v.fresh, false, v.causeUs, v.timing,
                               othersFollow);
            posted = true;
        }
        m_share.charge(id, m_share.now() - t0);
    }
    v.fresh = {};
    v.causeUs = 0;
    v.timing = {};
    return posted;
}

// Copies a chunk of the frame's rows (or the preview's) for its full image (copying a pixel costs
// ~1/30 of rendering it: a chunk of 4 x chunkPixels costs about four tiles' render); the copy
// done, every client waiting for the view's full image gets it.
void SimulationStep::copyChunk(ViewFrame& v) {
    const Dbi& from = v.copyingPreview ? v.preview : v.frame;
    const int width = std::max(from.width(), 1), height = from.height();
    const int rows =
        int(std::clamp<int64_t>(m_config.chunkPixels * 4 / width, 1, height - v.rowsCopied));
    const size_t at = size_t(v.rowsCopied) * size_t(width), n = size_t(rows) * size_t(width);
    std::memcpy(v.copy.color() + 4 * at, from.color() + 4 * at, 4 * n);
    std::memcpy(v.copy.depth() + at, from.depth() + at, sizeof(float) * n);
    v.rowsCopied += rows;
    if (v.rowsCopied < height)
        return;
    std::vector<std::pair<uint16_t, Client*>> waiting;
    for (uint16_t id : v.holders)
        if (Client& c = m_clients.at(id); c.fullCauseUs)
            waiting.emplace_back(id, &c);
    const Camera camera = v.copyingPreview ? previewCamera(v.camera) : v.camera;
    for (size_t i = 0; i < waiting.size(); ++i) {
        auto [id, c] = waiting[i];
        m_outbox.postFullImage(id, camera, i + 1 < waiting.size() ? v.copy : std::move(v.copy),
                               c->fullCauseUs, v.copyingPreview);
        if (!v.copyingPreview)
            c->fullCauseUs = 0; // a preview's clients still wait for the exact image
    }
    v.copy = Dbi();
    v.rowsCopied = -1;
    v.copyingPreview = false;
}

void SimulationStep::postRepairs() {
    for (uint16_t id : m_outbox.repairsWanted()) {
        auto c = m_clients.find(id);
        if (c == m_clients.end() || c->second.sync != Sync::Dbi || c->second.fullCauseUs)
            continue;
        auto v = std::find_if(m_views.begin(), m_views.end(),
                              [&](const ViewFrame& f) { return f.camera == c->second.camera; });
        if (v == m_views.end() || !v->settled())
            continue;
        const uint64_t t0 = m_share.now();
        m_outbox.postImage(id, v->camera, v->frame, {}, false, 0, {});
        m_share.charge(id, m_share.now() - t0);
    }
}

void SimulationStep::renderBulkApart(int nice, Executor& freer) {
    m_freer = &freer;
    m_bulkPool = std::make_unique<ThreadPool>(m_pool.size(), "trephine-bulk", nice);
    m_renderer->setBulkPool(m_bulkPool.get());
    m_bulkNudged.store(m_bulkPool.get(), std::memory_order_release);
}

void SimulationStep::yieldChanged() {
    if (ThreadPool* pool = m_bulkNudged.load(std::memory_order_acquire))
        pool->nudge();
}

size_t SimulationStep::viewCount() const {
    return size_t(
        std::count_if(m_views.begin(), m_views.end(), [](const ViewFrame& v) { return !v.kept; }));
}

int64_t SimulationStep::viewPixels() const {
    int64_t total = 0;
    for (const ViewFrame& v : m_views)
        total += pixelsOf(v.frame);
    return total;
}

// [SECTION] inspection

Dbi SimulationStep::render(const Camera& camera) {
    syncGrid();
    return m_renderer->render(camera);
}

} // namespace trephine::net
