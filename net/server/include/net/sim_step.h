// The session server's simulation step: it owns the volume, the renderer and one frame per
// distinct view, and turns a batch of events (joins, views, mode switches, tool states, cuts) into
// changed voxels and rendered BB_screen rectangles, which it posts to the outbox. Time is passed
// in; the server's simulation thread pumps it, and tests call step() directly, with no ENet.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/dbi_renderer.h"
#include "libsim/drill.h"
#include "libsim/renderer.h"
#include "libsim/thread_pool.h"
#include "libsim/tool.h"
#include "libsim/volume.h"
#include "net/assessment.h"
#include "net/budgets.h"
#include "net/events.h"
#include "net/fair_share.h"
#include "net/outbox.h"
#include "net/protocol.h"
#include "net/server_report.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <shared_mutex>
#include <span>
#include <vector>

namespace trephine::net {

struct StepConfig {
    float maxStepS = 0.05f;        // ServerConfig::maxStepS
    float maxSweepMm = 10.0f;      // ServerConfig::maxSweepMm
    int renderThreads = 0;         // 0: hardware concurrency
    AssessmentConfig assessment{}; // zones; its maxSweepMm is taken from maxSweepMm
    // The views' work goes a piece at a time, the peer whose turn it is first (net/fair_share.h),
    // and the step stops after any piece once `yield` says events wait: they are applied first
    // (docs/session.md, "Availability"). New views' rows come in bands of chunkPixels' worth
    // of rows, at most slicePixels a step; a band also stops at the next column of tiles once
    // events wait. A change of a view of at most slicePixels is one piece; a larger view's
    // change goes in pieces of at most chunkPixels.
    int64_t slicePixels = int64_t(1) << 18;
    int64_t chunkPixels = int64_t(1) << 13;
    // A new view of more pixels than this is first rendered at half width and height (a quarter
    // of the rays, in pieces as its rows are), upsampled and sent as its full image, then the
    // exact frame follows as today (docs/session.md, "Progressive first pictures"). 0: never.
    int64_t previewPixels = int64_t(1) << 18;
    // A whole view its last client lets go (a leave, a switch to volume, a view change) is kept,
    // unrendered but its changes noted, for keepViewUs, so a client that asks for the same camera
    // again (a reconnect, a switch back, a preset toggled back) gets it for the re-render of what
    // changed meanwhile. At most keptPixels are kept, each view counted as at least
    // kKeptViewFloorPixels: past them, the oldest view of the peer keeping the most goes
    // (docs/session.md, "Kept views"). 0: none.
    uint64_t keepViewUs = 60'000'000;
    int64_t keptPixels = int64_t(1) << 22;
    static constexpr int64_t kKeptViewFloorPixels = int64_t(1) << 16;
    // Measures the work charged to peers (FairShare); empty: the steady clock. Not the step's
    // clock: a pumped server's stands still within a pass.
    ServerClock workClock = {};
    // True when events wait for the next step (the server: its queue is not empty); empty:
    // never. Asked on the simulation thread and, within bulk pieces, on the render threads at
    // once (Renderer::renderBulk): it must be safe to call from several threads.
    std::function<bool()> yield = {};
    // Returns once what was posted has been handed to the network (or a bound has passed). The
    // step calls it before a piece of chunked work for another peer than those just given an
    // update, so the piece does not take the cores their send needs; it holds the step meanwhile.
    // Empty: never (the server's waits only while its network thread runs).
    std::function<void()> letSend = {};
    // Post updates to the outbox (a server). A replay (net/session_replay.h) only drills: it
    // renders nothing until asked (render()).
    bool publish = true;
    // What renders the views (ServerConfig::renderer); empty: the CPU ray caster.
    DbiRendererFactory renderer = {};
};

class SimulationStep {
public:
    // Labels every density-0 voxel Air (see normaliseAir in the source).
    SimulationStep(Volume volume, const StepConfig& config, Outbox& outbox, ReportBook& book,
                   ServerClock clock);

    // Applies the events of `batch` in arrival order at server time `now` (the cause time of the
    // full updates a join or a switch needs; a record's time is when its event arrived, 0: now),
    // then posts: the changed voxels (or the whole volume) to volume clients first, then
    // BB_screen, rendered once per distinct view, to DBI clients. The policy's decisions in it
    // (hellos, marks, take-overs) are not the simulation's: it skips them.
    void step(std::span<const LogRecord> batch, uint64_t now);
    // With nothing to apply: held-back volume clients' noted changes go once they can.
    void offerNoted() { m_outbox.offerNoted(m_volume); }
    // After step() or offerNoted(): a client that reported a lost rectangle, whose view has no
    // change under way (that change's update repairs it), gets the rectangles it has not
    // acknowledged, at current pixels, charged to it.
    void postRepairs();
    // The assessment of every applied tool state (its notices go out on the network thread).
    Assessment& assessment() { return m_assessment; }

    // A fresh full render of the current volume (what a converged client holds).
    Dbi render(const Camera& camera);
    // The voxels: written only by step(), under voxelMutex() held exclusively around each write,
    // so another thread may read them under a shared lock (the haptic answer).
    const Volume& volume() const { return m_volume; }
    // What renders the views ("CPU, 2 threads", "GPU: ..."), after any fallback.
    std::string rendererName() const { return m_renderer->describe(); }
    std::shared_mutex& voxelMutex() { return m_voxelMutex; }
    // Re-render every view whole on each change (the paper's way) instead of BB_screen only.
    void setFullRender(bool on) { m_fullRender = on; }
    // Views some DBI client holds; and those kept after their last client let go (keepViewUs).
    size_t viewCount() const;
    size_t keptViewCount() const { return m_views.size() - viewCount(); }
    // [Any thread] Some view's work is not done: step() has work even with no events.
    bool rendering() const { return m_rendering.load(); }
    // The simulation thread's time charged to each peer (the views it holds, its updates' and
    // volume transfers' coding).
    const FairShare& share() const { return m_share; }
    // The pixels of every view frame held (the server's memory grows with them).
    int64_t viewPixels() const;
    // [Before the first step] New views' rows render on background threads at `nice`
    // (ThreadPool's background kind), so they take only what others' updates, the network and
    // the clients leave of the CPU, and dropped views' frames are freed on `freer`; the server
    // does this when it runs its threads.
    void renderBulkApart(int nice, Executor& freer);
    // [Any thread] What StepConfig::yield reads has changed: a bulk piece whose background threads
    // wait for the CPU asks it again now, instead of when one of them next finishes a column.
    void yieldChanged();

private:
    // A participant as the simulation sees it: its view and its tool.
    struct Client {
        Camera camera;
        Sync sync = Sync::Dbi;
        std::optional<Driller> driller;
        ToolPose lastPose;         // of the newest applied tool state
        bool lastDrilling = false; // it drilled (with the driller there is now)
        uint64_t fullCauseUs = 0;  // waits for a full image of its view (since this cause)
        bool hasTool = false;
        uint32_t lastSequence = 0;
        uint64_t lastClientUs = 0;
        bool views(const Camera& view) const { return sync == Sync::Dbi && camera == view; }
    };
    // One render per distinct view; clients that share a camera share its frame.
    struct ViewFrame {
        Camera camera;
        Dbi frame;
        HitCache cache;   // where each pixel's ray met bone: dirty re-renders resume there
        int rowsDone = 0; // rows rendered so far: the frame is whole at frame.height()
        int colsDone = 0, bandRows = 0; // the band of rows under way after them: its columns done
        std::vector<uint16_t> holders;  // the DBI clients viewing it, charged for its work
        // Held by nobody since keptUs (StepConfig::keepViewUs), let go last by keptBy (0: a peer
        // gone whose id is in use again); keptOrder ranks it among the kept, oldest first.
        bool kept = false;
        uint64_t keptUs = 0, keptOrder = 0;
        uint16_t keptBy = 0;
        // Changed pixels (of the rows done) still to render, and those rendered since the
        // view's clients last got them; the oldest cause and the stage times they carry.
        PixelRect stale, fresh;
        // Every voxel changed since the stale pixels were rendered (their re-render keeps the
        // pixels whose cached hit is clear of it); restaled: render them all.
        Box3i staleBox;
        bool staleAll = false;
        uint64_t causeUs = 0;
        ImageTiming timing;
        // A full image coded apart (SimulationStep::copiedApart): the copy of the frame it is
        // coded from, made in chunks (the frame holds still meanwhile); -1: none under way.
        Dbi copy;
        int rowsCopied = -1;
        bool copyingPreview = false; // the copy is of the preview below
        // A view larger than previewPixels, new: its half-size render (previewCamera) so far;
        // -1: no preview under way (none, or sent).
        Dbi preview;
        int previewRows = -1, previewCols = 0, previewBand = 0;
        bool previewing() const { return previewRows >= 0; }
        bool whole() const { return rowsDone >= frame.height(); }
        bool copying() const { return rowsCopied >= 0; }
        bool settled() const { return whole() && stale.empty() && !copying(); }
        void staleRendered() {
            stale = {};
            staleBox = {};
            staleAll = false;
        }
    };
    // What one batch changed and who needs a full update.
    struct Batch {
        Box3i changed;
        uint64_t causeUs = 0;                    // the oldest cause of a change
        uint64_t erodeUs = 0;                    // erosion and cuts
        bool materials = false;                  // voxels written wholesale
        std::map<uint16_t, uint64_t> needFull;   // DBI client -> cause time of a full DBI
        std::map<uint16_t, uint64_t> needVolume; // volume client -> cause time of a full volume
        void changedBy(const Box3i& box, uint64_t arrivedUs);
    };

    // `at`: the event's time (its record's, else the step's), for the assessment.
    void applyJoin(const JoinEvent& ev, uint64_t at, Batch& b, uint64_t now);
    void applyView(const ViewEvent& ev, Batch& b, uint64_t now);
    void applySync(const SyncEvent& ev, Batch& b, uint64_t now);
    void applyLeave(const LeaveEvent& ev, uint64_t at, Batch& b);
    void applyCut(const CutEvent& ev, uint64_t arrivedUs, Batch& b);
    void applyVoxels(const VoxelsEvent& ev, uint64_t arrivedUs, Batch& b);
    void applyTool(const ToolEvent& ev, uint64_t arrivedUs, uint64_t at, Batch& b);
    void postVolumes(const Batch& b);
    uint32_t updateGrid(const Batch& b);
    void renderViews(const Batch& b, uint32_t gridUs, uint64_t now);
    void keepOrDrop(std::vector<ViewFrame>& dropped, uint64_t now);
    void restale(ViewFrame& v);
    void markChanged(ViewFrame& v, const Batch& b, uint32_t gridUs);
    void schedule();
    void workOn(ViewFrame& v, int64_t& rowsLeft, int64_t atLeast);
    int64_t bandPiece(const Camera& camera, Dbi& frame, HitCache* cache, int& rows, int& cols,
                      int& band, int64_t rowsLeft, int64_t atLeast);
    bool copiedApart(const ViewFrame& v) const;
    void renderStale(ViewFrame& v);
    void previewChunk(ViewFrame& v, int64_t& rowsLeft, int64_t atLeast);
    void postPreview(ViewFrame& v);
    bool large(const ViewFrame& v) const;
    bool postView(ViewFrame& v); // true if it posted an update
    void letSend(const ViewFrame& v, uint16_t peer);
    void copyChunk(ViewFrame& v);
    void syncGrid();

    StepConfig m_config;
    Outbox& m_outbox;
    ReportBook& m_book;
    ServerClock m_clock;
    std::shared_mutex m_voxelMutex;
    Volume m_volume;
    ThreadPool m_pool;
    std::unique_ptr<ThreadPool> m_bulkPool; // renderBulkApart's; null: m_pool does it all
    // m_bulkPool for yieldChanged, which any thread that queues events calls, start() or not.
    std::atomic<ThreadPool*> m_bulkNudged{nullptr};
    // Where dropped views' frames are freed: a 2048 x 2048 view's frame, hit cache and preview
    // took the step 4-7 ms to free. Inline (the simulation thread) unless renderBulkApart.
    InlineExecutor m_inlineFreer;
    Executor* m_freer = &m_inlineFreer;
    // Set when the configured renderer failed and the CPU's took over: the views' pixels so far
    // are the failed renderer's, re-rendered by the next step.
    bool m_rendererReplaced = false;
    std::unique_ptr<DbiRenderer> m_renderer; // StepConfig::renderer, else the CPU ray caster
    Assessment m_assessment;
    std::map<uint16_t, Client> m_clients;
    std::vector<ViewFrame> m_views;
    // Changes the renderer's brick grid has not taken yet. It is rendering data for DBI views,
    // kept in step only while some client is in DBI mode (a volume-only session pays nothing for
    // it), and brought up to date before the next render.
    Box3i m_gridPending;
    bool m_gridRebuildPending = false;
    std::atomic<bool> m_fullRender{false};
    std::atomic<bool> m_rendering{false};
    FairShare m_share;              // StepConfig::workClock
    uint64_t m_keptViews = 0;       // views kept so far (ViewFrame::keptOrder)
    std::vector<uint16_t> m_posted; // peers given an update in the step since the last letSend
};

} // namespace trephine::net
