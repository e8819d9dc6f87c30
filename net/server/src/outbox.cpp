#include "net/outbox.h"

#include "net/codec.h"
#include "net/image_delta.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace trephine::net {

Outbox::Outbox(int64_t maxInFlightBytes, ReportBook& book, ServerClock clock,
               std::function<void()> wake)
    : m_maxInFlightBytes(maxInFlightBytes), m_book(book), m_clock(std::move(clock)),
      m_wake(std::move(wake)) {}

Outbox::~Outbox() {
    m_coder->cancel(); // a job runs `wake` and fills this outbox's images
}

// [SECTION] clients

void Outbox::join(uint16_t id, Host::InFlight inFlight, Codec codec, Codec volumeCodec) {
    Client& c = m_clients[id];
    c = Client{};
    c.inFlight = std::move(inFlight);
    c.codec = codec;
    c.volumeCodec = volumeCodec;
    countNoted();
    std::lock_guard lock(m_mutex);
    m_lossy[id] = Lossy{};
}

void Outbox::leave(uint16_t id) {
    m_clients.erase(id);
    countNoted();
    std::lock_guard lock(m_mutex);
    m_images.erase(id);
    m_volumes.erase(id);
    m_lossy.erase(id);
}

void Outbox::viewChanged(uint16_t id, uint32_t viewId) {
    m_clients[id].viewId = viewId;
    std::lock_guard lock(m_mutex);
    m_images.erase(id);
    resetLossy(id, viewId, 0); // rectangles wait for the new view's full image
}

void Outbox::modeChanged(uint16_t id, Sync mode, Codec volumeCodec) {
    Client& c = m_clients[id];
    c.volumeCodec = volumeCodec;
    if (mode == Sync::Volume) {
        c.shadow = Dbi(); // the next DBI it gets is a full one
    } else {
        c.noted.reset();
        countNoted();
    }
    std::lock_guard lock(m_mutex);
    resetLossy(id, c.viewId, 0); // either way the next DBI is a full one
    if (mode == Sync::Volume)
        m_images.erase(id);
    else
        m_volumes.erase(id);
}

void Outbox::clear() {
    m_coder->cancel(); // a job may call `wake`, whose target goes when the server does
    for (auto& [id, c] : m_clients)
        c.noted.reset();
    countNoted();
    std::lock_guard lock(m_mutex);
    m_images.clear();
    m_volumes.clear();
    m_refused.clear();
    m_lossy.clear();
    m_coded = {};
}

const Dbi* Outbox::shadow(uint16_t id) const {
    auto it = m_clients.find(id);
    return it == m_clients.end() ? nullptr : &it->second.shadow;
}

bool Outbox::heldBack(const Host::InFlight& inFlight) const {
    return inFlight && inFlight->load(std::memory_order_relaxed) > m_maxInFlightBytes;
}

bool Outbox::empty() const {
    if (m_noted.load() > 0)
        return false;
    std::lock_guard lock(m_mutex);
    return m_images.empty() && m_volumes.empty();
}

void Outbox::countNoted() {
    m_noted = int(std::count_if(m_clients.begin(), m_clients.end(),
                                [](const auto& kv) { return kv.second.noted.has_value(); }));
}

// [SECTION] images

void Outbox::postImage(uint16_t id, const Camera& camera, const Dbi& frame, PixelRect rect,
                       bool full, uint64_t causeUs, ImageTiming timing, bool othersFollow) {
    post(id, camera, frame, rect, full, causeUs, timing, nullptr, false, othersFollow);
}

void Outbox::postFullImage(uint16_t id, const Camera& camera, Dbi pixels, uint64_t causeUs,
                           bool preview) {
    post(id, camera, pixels, pixels.bounds(), true, causeUs, {}, &pixels, preview);
}

Dbi Outbox::buffer(int width, int height) {
    {
        std::lock_guard lock(m_mutex);
        // One of another size stays for the next full image.
        if (m_spare.width() == width && m_spare.height() == height)
            return std::exchange(m_spare, Dbi()); // a moved-from Dbi keeps its size, not pixels
    }
    return Dbi::unfilled(width, height);
}

// `owned`: `frame` itself, which a full image coded apart takes instead of a copy.
void Outbox::post(uint16_t id, const Camera& camera, const Dbi& frame, PixelRect rect, bool full,
                  uint64_t causeUs, ImageTiming timing, Dbi* owned, bool preview,
                  bool othersFollow) {
    Client& c = m_clients[id];
    LossyBase base;
    std::optional<PendingImage> old = takeMergeable(id, c.viewId, full, causeUs, base);
    // Not of this frame (a view change drops waiting images; this is the safety net): the
    // client's pixels are unknown, so it gets the whole frame.
    const bool merge = old && frame.bounds().contains(old->rect);
    if (old && !merge)
        full = true;
    if (merge) {
        // It never left: the client does not have its pixels.
        if (!old->full && !old->undo.empty() && !c.shadow.empty())
            c.shadow.apply(old->undo, old->rect.x, old->rect.y);
        rect = unite(rect, old->rect);
        full = full || old->full;
        causeUs = std::min(causeUs, old->causeUs);
    }
    // After a full image a rectangle goes lossy once the client has acknowledged that full image
    // (before, a lossy one would overtake it and be ignored), chained or self-contained.
    const bool afterFull = !full && base.fullSequence != 0;
    const uint32_t baseSequence = afterFull ? chainOn(c, base, merge ? &*old : nullptr) : 0;
    const bool chained = baseSequence != 0;
    if (afterFull && !chained) {
        if (causeUs == 0) // a repair: what it carries was caused that long ago
            causeUs = base.unackedCauseUs;
        if (!base.unacked.empty())
            rect = rect.empty() ? base.unacked : unite(rect, base.unacked);
    }
    rect = full ? frame.bounds() : intersect(rect, frame.bounds());
    if (rect.empty()) {
        if (afterFull && !chained)
            postedSelfContained(id, c.lastPosted); // nothing left to repair
        return;
    }
    ImageUpdate u;
    u.sequence = ++m_sequence;
    u.viewId = c.viewId;
    u.fullSequence = afterFull ? base.fullSequence : 0;
    u.baseSequence = baseSequence;
    c.lastPosted = u.sequence;
    if (full) {
        std::lock_guard lock(m_mutex);
        resetLossy(id, c.viewId, u.sequence); // it says all the rectangles before it said
    } else if (afterFull && !chained) {
        postedSelfContained(id, u.sequence);
    }
    u.causeServerUs = causeUs;
    u.full = full;
    u.preview = full && preview;
    u.x = uint16_t(rect.x);
    u.y = uint16_t(rect.y);
    u.width = uint16_t(rect.w);
    u.height = uint16_t(rect.h);
    // A raw rectangle too large for one message goes lz4-coded (see kMaxImagePayloadBytes).
    u.codec = c.codec == Codec::Raw && uint64_t(rect.area()) * 8 > kMaxImagePayloadBytes
                  ? Codec::Lz4
                  : c.codec;
    if (full && (owned || codesApart(rect.area()))) {
        postApart(id, c, camera, frame, owned, std::move(u));
        return;
    }
    const uint64_t e0 = m_clock();
    const Dbi pixels = frame.extract(rect);
    Dbi undo = encodeInto(u, c, frame, pixels, camera, !afterFull || chained, othersFollow);
    // Only zstd clients get predicted updates, so only they need the copy (a whole frame:
    // 33.5 MB for 2048 x 2048).
    if (c.codec != Codec::Zstd)
        c.shadow = Dbi();
    else if (full)
        c.shadow = frame;
    else if (!c.shadow.empty())
        c.shadow.apply(pixels, rect.x, rect.y);
    stampTimes(u, timing, e0);
    PendingImage p{c.viewId,
                   rect,
                   full,
                   causeUs,
                   u.rawBytes,
                   uint32_t(u.payload.size()),
                   encodeMessage(u),
                   std::move(undo),
                   c.inFlight};
    p.afterFull = afterFull;
    p.lossy = afterFull && base.based && p.message.size() <= kLossyMaxMessageBytes;
    p.sequence = u.sequence;
    p.baseSequence = baseSequence;
    {
        std::lock_guard lock(m_mutex);
        m_images[id].push_back(std::move(p));
    }
    if (m_wake)
        m_wake();
}

// The image a chained rectangle builds on (the one posted before it, or the one a merged one
// built on; the shadow holds it), or 0: self-contained, carrying every one not acknowledged.
// Self-contained: from a client that lost one lately, merged with a self-contained one, or after
// a reliable one not yet acknowledged (a lossy chained one would overtake it; a reliable one
// would make every later one reliable).
uint32_t Outbox::chainOn(const Client& c, const LossyBase& base, const PendingImage* merged) {
    const uint32_t on = merged ? merged->baseSequence : c.lastPosted;
    const bool behindReliable =
        base.based && std::count(base.reliableUnacked.begin(), base.reliableUnacked.end(), on);
    return base.chain && !behindReliable ? on : 0;
}

// A full image coded apart, from `owned` or a copy of `frame`.
void Outbox::postApart(uint16_t id, Client& c, const Camera& camera, const Dbi& frame, Dbi* owned,
                       ImageUpdate u) {
    // Only zstd clients get predicted updates, so only they need the copy; a preview is none
    // (rectangles wait for the exact full image).
    c.shadow = c.codec == Codec::Zstd && !u.preview ? frame : Dbi();
    Dbi pixels;
    if (owned) {
        pixels = std::move(*owned);
    } else {
        // Into the coder's last buffer when it fits: a fresh one costs ~20 ms of page faults.
        pixels = buffer(frame.width(), frame.height());
        pixels = frame; // a full image: the frame's bounds
    }
    codeApart(id, CodingJob{id, 0, std::move(u), std::move(pixels), camera});
}

// The update's stage times (its coding began at `codedFromUs`), in it and in the report.
void Outbox::stampTimes(ImageUpdate& u, ImageTiming timing, uint64_t codedFromUs) {
    u.sentServerUs = m_clock();
    u.erodeUs = timing.erodeUs;
    u.renderUs = timing.renderUs;
    u.gridUs = std::min(timing.gridUs, timing.renderUs);
    u.encodeUs = uint32_t(u.sentServerUs - codedFromUs);
    m_book.record([&](ServerReport& r) {
        ModeReport& m = r.modes[size_t(Sync::Dbi)];
        m.encodeUs.add(double(u.encodeUs));
        if (!u.full) {
            m.erodeUs.add(double(timing.erodeUs));
            m.renderUs.add(double(timing.renderUs));
        }
    });
}

// [Posting thread] Takes the client's newest waiting image when the new one merges with it; a full
// image clears them all (keeping their oldest cause), an image of an older view is dropped.
std::optional<Outbox::PendingImage> Outbox::takeMergeable(uint16_t id, uint32_t viewId, bool full,
                                                          uint64_t& causeUs, LossyBase& base) {
    std::lock_guard lock(m_mutex);
    if (auto it = m_lossy.find(id); it != m_lossy.end() && it->second.viewId == viewId) {
        const Lossy& l = it->second;
        base.fullSequence = l.fullSequence;
        base.chain = !l.repairWanted;
        base.based = l.based;
        for (const SentRect& r : l.unacked) {
            base.unacked = base.unacked.empty() ? r.rect : unite(base.unacked, r.rect);
            base.unackedCauseUs =
                base.unackedCauseUs ? std::min(base.unackedCauseUs, r.causeUs) : r.causeUs;
            if (r.reliable)
                base.reliableUnacked.push_back(r.sequence);
        }
    }
    auto it = m_images.find(id);
    if (it == m_images.end())
        return std::nullopt;
    std::optional<PendingImage> old;
    std::vector<PendingImage>& waiting = it->second;
    if (full) {
        // The whole frame says all they said (a job coding one of them is dropped).
        for (const PendingImage& w : waiting)
            if (w.viewId == viewId)
                causeUs = std::min(causeUs, w.causeUs);
        waiting.clear();
    } else if (!waiting.empty() && waiting.back().viewId != viewId) {
        waiting.clear();
    } else if (!waiting.empty() && !waiting.back().ticket) {
        // The newest merges unless it is a full image coded apart: that one is never coded
        // again, and this rectangle waits behind it.
        old = std::move(waiting.back());
        waiting.pop_back();
    }
    if (waiting.empty())
        m_images.erase(it);
    return old;
}

// Codes `pixels` (the update's rectangle of `frame`) into `u`: predicted against the client's
// copy for zstd clients when `predictable`, planar otherwise. Gives the copy's pixels it replaces
// (empty for a full image or a client without a copy), which a merge puts back.
Dbi Outbox::encodeInto(ImageUpdate& u, const Client& c, const Dbi& frame, const Dbi& pixels,
                       const Camera& camera, bool predictable, bool keep) {
    const bool copied = !u.full && c.codec == Codec::Zstd && c.shadow.width() == frame.width() &&
                        c.shadow.height() == frame.height();
    Dbi undo = copied ? c.shadow.extract({int(u.x), int(u.y), int(u.width), int(u.height)}) : Dbi();
    // Predicted updates trade ~4 ns a pixel more coding at each end than the planar form for
    // about half its bytes (benchmark_net 'predicted|planar'): worth it with zstd (the codec
    // chosen for bytes), not with lz4 (chosen for latency).
    const bool predicted = copied && predictable;
    const Codec codec = predicted ? c.codec : u.codec;
    u.predicted = predicted;
    if (reuseCoding(u, camera, codec, pixels, undo))
        return undo;
    if (predicted) {
        PredictedImage p = encodePredicted(pixels, undo, codec, DepthQuantizer(camera));
        u.baseHash = p.baseHash;
        u.rawBytes = p.rawBytes;
        u.payload = std::move(p.payload);
    } else {
        EncodedImage e = encodeImage(pixels, codec, camera);
        u.rawBytes = e.rawBytes;
        u.payload = std::move(e.payload);
    }
    // Kept (two copies of the pixels) only for clients that follow: a lone client would pay the
    // copies for nothing. An empty payload keeps nothing.
    m_coded = keep ? Coded{camera,     codec,      predicted, pixels, predicted ? undo : Dbi(),
                           u.baseHash, u.rawBytes, u.payload}
                   : Coded{};
    return undo;
}

// Fills `u` with the kept coding when it is of the same pixels, coded the same way against the
// same copy (`base`, predicted): the payload depends on nothing else.
bool Outbox::reuseCoding(ImageUpdate& u, const Camera& camera, Codec codec, const Dbi& pixels,
                         const Dbi& base) {
    const Coded& m = m_coded;
    if (m.payload.empty() || m.camera != camera || m.codec != codec || m.predicted != u.predicted ||
        !(m.pixels == pixels) || (u.predicted && !(m.base == base)))
        return false;
    u.baseHash = m.baseHash;
    u.rawBytes = m.rawBytes;
    u.payload = m.payload;
    m_book.count(&ServerCounters::codingsShared);
    return true;
}

// [Posting thread] Every rectangle before `sequence` is in it (or acknowledged): a loss reported
// of one of them is repaired.
void Outbox::postedSelfContained(uint16_t id, uint32_t sequence) {
    std::lock_guard lock(m_mutex);
    if (auto it = m_lossy.find(id); it != m_lossy.end()) {
        it->second.repairWanted = false;
        it->second.selfContained = sequence;
    }
}

std::vector<uint16_t> Outbox::repairsWanted() const {
    std::vector<uint16_t> ids;
    std::lock_guard lock(m_mutex);
    for (const auto& [id, l] : m_lossy)
        if (l.repairWanted && !m_images.count(id))
            ids.push_back(id);
    return ids;
}

// The full image waits, being coded, at the end of the client's images; the coder fills in its
// message, and the network takes nothing of the client's from it on until then.
void Outbox::codeApart(uint16_t id, CodingJob job) {
    PendingImage p;
    p.viewId = job.update.viewId;
    p.rect = {0, 0, job.pixels.width(), job.pixels.height()};
    p.full = true;
    p.sequence = job.update.sequence;
    p.causeUs = job.update.causeServerUs;
    p.inFlight = m_clients[id].inFlight;
    p.coding = true;
    p.preview = job.update.preview;
    {
        std::lock_guard lock(m_mutex);
        p.ticket = job.ticket = ++m_tickets;
        m_images[id].push_back(std::move(p));
    }
    auto shared = std::make_shared<CodingJob>(std::move(job));
    m_coder->post([this, shared] { code(std::move(*shared)); });
}

// [Coder] Codes a full image posted apart and hands its message to the waiting image.
void Outbox::code(CodingJob job) {
    ImageUpdate& u = job.update;
    const uint64_t e0 = m_clock();
    EncodedImage e = encodeImage(job.pixels, u.codec, job.camera);
    u.rawBytes = e.rawBytes;
    u.payload = std::move(e.payload);
    u.sentServerUs = m_clock();
    u.encodeUs = uint32_t(u.sentServerUs - e0);
    m_book.record(
        [&](ServerReport& r) { r.modes[size_t(Sync::Dbi)].encodeUs.add(double(u.encodeUs)); });
    std::vector<uint8_t> message = encodeMessage(u);
    bool done = false;
    {
        std::lock_guard lock(m_mutex);
        if (!u.preview) // a view's frames are the buffers worth keeping, not its half-size preview
            m_spare = std::move(job.pixels);
        if (auto it = m_images.find(job.client); it != m_images.end())
            for (PendingImage& p : it->second)
                if (p.ticket == job.ticket && p.coding) {
                    p.rawBytes = u.rawBytes;
                    p.payloadBytes = uint32_t(u.payload.size());
                    p.message = std::move(message);
                    p.coding = false;
                    done = true;
                }
    }
    if (done && m_wake)
        m_wake();
}

void Outbox::finishCoding() {
    m_coder->drain();
}

// [SECTION] volumes

// Codes `change` merged with the client's waiting volume update: the union box, taken from the
// volume now. False when the update does not fit a message (nothing is posted then).
bool Outbox::postVolume(uint16_t id, const Client& c, const Volume& volume, VolumeChange change) {
    std::optional<PendingVolume> old;
    {
        std::lock_guard lock(m_mutex);
        auto it = m_volumes.find(id);
        if (it != m_volumes.end()) {
            old = std::move(it->second);
            m_volumes.erase(it);
        }
    }
    if (old) {
        change.box.merge(old->change.box);
        change.full = change.full || old->change.full;
        change.materials = change.materials || old->change.materials;
        change.causeUs = std::min(change.causeUs, old->change.causeUs);
    }
    Box3i box = change.full ? volume.bounds() : change.box.intersect(volume.bounds());
    if (box.empty())
        return true;
    change.box = box;
    VolumeUpdate u;
    u.sequence = ++m_sequence;
    u.causeServerUs = change.causeUs;
    u.full = change.full;
    u.materials = change.full || change.materials;
    u.x = uint16_t(box.lo.x);
    u.y = uint16_t(box.lo.y);
    u.z = uint16_t(box.lo.z);
    const glm::ivec3 size = box.size();
    u.sizeX = uint16_t(size.x);
    u.sizeY = uint16_t(size.y);
    u.sizeZ = uint16_t(size.z);
    // More raw bytes than a VolumeUpdate may announce cannot go, however well they code: refused
    // before anything is built and compressed.
    if (!fitsVolumeUpdate(size, u.materials))
        return false;
    const uint64_t e0 = m_clock();
    EncodedVolume e = change.full ? encodeVolumeFull(volume, c.volumeCodec)
                                  : encodeVolumeBox(volume, box, c.volumeCodec, change.materials);
    u.codec = e.codec;
    u.rawBytes = e.rawBytes;
    u.payload = std::move(e.payload);
    u.sentServerUs = m_clock();
    u.erodeUs = change.erodeUs;
    u.encodeUs = uint32_t(u.sentServerUs - e0);
    m_book.record([&](ServerReport& r) {
        ModeReport& m = r.modes[size_t(Sync::Volume)];
        m.encodeUs.add(double(u.encodeUs));
        if (!change.full)
            m.erodeUs.add(double(change.erodeUs));
    });
    std::vector<uint8_t> message = encodeMessage(u);
    if (message.empty() || message.size() > kMaxSentMessageBytes)
        return false; // too large once coded to go through ENet
    PendingVolume p{change, u.rawBytes, uint32_t(u.payload.size()), std::move(message), c.inFlight};
    {
        std::lock_guard lock(m_mutex);
        m_volumes[id] = std::move(p);
    }
    if (m_wake)
        m_wake();
    return true;
}

void Outbox::postVolumeOrRefuse(uint16_t id, const Client& c, const Volume& volume,
                                const VolumeChange& change) {
    if (postVolume(id, c, volume, change))
        return;
    if (!change.full &&
        postVolume(id, c, volume, VolumeChange{volume.bounds(), true, true, change.causeUs, 0}))
        return;
    {
        std::lock_guard lock(m_mutex);
        m_volumes.erase(id);
        m_refused.push_back(id);
    }
    if (m_wake)
        m_wake();
}

void Outbox::offerVolume(uint16_t id, const Volume& volume, std::optional<VolumeChange> change) {
    Client& c = m_clients[id];
    if (c.noted) {
        if (change) {
            change->box.merge(c.noted->box);
            change->full = change->full || c.noted->full;
            change->materials = change->materials || c.noted->materials;
            change->causeUs = std::min(change->causeUs, c.noted->causeUs);
            change->erodeUs += c.noted->erodeUs;
        } else {
            change = c.noted;
        }
    }
    if (!change)
        return;
    // Re-coding a waiting update at every batch would cost a slow link's client a whole
    // volume's encode per batch: while it is held back with one waiting, changes are noted.
    bool waiting = false;
    if (heldBack(c.inFlight)) {
        std::lock_guard lock(m_mutex);
        waiting = m_volumes.count(id) > 0;
    }
    if (waiting) {
        c.noted = change;
    } else {
        c.noted.reset();
        postVolumeOrRefuse(id, c, volume, *change);
    }
    countNoted();
}

void Outbox::offerNoted(const Volume& volume) {
    if (m_noted.load() == 0)
        return;
    for (auto& [id, c] : m_clients)
        if (c.noted)
            offerVolume(id, volume, std::nullopt);
}

// [SECTION] network side

Outbox::Taken Outbox::take(const std::function<bool(uint16_t)>& live) {
    Taken taken;
    const uint64_t now = m_clock();
    std::lock_guard lock(m_mutex);
    taken.refused.swap(m_refused);
    // A live client with too much still in ENet's hands, or too many lossy bytes unacknowledged,
    // gets nothing now: its update stays here, where the next changes merge into it. A client's
    // images go in order, up to one still being coded.
    for (auto it = m_images.begin(); it != m_images.end();) {
        const bool isLive = live(it->first);
        std::vector<PendingImage>& waiting = it->second;
        const auto held = [&](PendingImage& p) {
            auto l = m_lossy.find(it->first);
            // A full image waits for what ENet holds of the client's, lossy or not; a rectangle
            // too large to go lossy waits for a lossy full image's acknowledgement (reliable, it
            // could overtake it and be ignored).
            if (!sendsLossy(it->first, p) || (p.full && heldBack(p.inFlight)))
                return heldBack(p.inFlight) ||
                       (p.afterFull && l != m_lossy.end() && l->second.fullUnacked());
            return l != m_lossy.end() && lossyHeldBack(l->second, now);
        };
        size_t n = 0;
        for (; isLive && n < waiting.size() && !waiting[n].coding && !held(waiting[n]); ++n) {
            PendingImage& p = waiting[n];
            if (p.afterFull)
                sentAfterFull(it->first, p, now);
            else if (p.full)
                sentFull(it->first, p, now);
            auto l = m_lossy.find(it->first);
            taken.updates.push_back({it->first, Sync::Dbi,
                                     p.lossy ? Channel::ImageLossy : Channel::Image, p.full,
                                     p.payloadBytes, p.rawBytes, std::move(p.message),
                                     p.lossy && l != m_lossy.end() ? parityLoss(l->second) : 0});
        }
        waiting.erase(waiting.begin(), isLive ? waiting.begin() + long(n) : waiting.end());
        it = waiting.empty() ? m_images.erase(it) : std::next(it);
    }
    takeRepairs(live, now, taken);
    for (auto it = m_volumes.begin(); it != m_volumes.end();) {
        const bool isLive = live(it->first);
        PendingVolume& p = it->second;
        if (isLive && heldBack(p.inFlight)) {
            ++it;
            continue;
        }
        if (isLive)
            taken.updates.push_back({it->first, Sync::Volume, Channel::Volume, p.change.full,
                                     p.payloadBytes, p.rawBytes, std::move(p.message)});
        it = m_volumes.erase(it);
    }
    return taken;
}

// [SECTION] lossy rectangles

void Outbox::resetLossy(uint16_t id, uint32_t viewId, uint32_t fullSequence) {
    auto it = m_lossy.find(id);
    if (it == m_lossy.end())
        return;
    Lossy& l = it->second;
    const Lossy path = l; // its round trips and delivery are the path's, whatever the view
    l = Lossy{};
    l.viewId = viewId;
    l.fullSequence = fullSequence;
    l.selfContained = fullSequence; // nothing before the full image needs repair
    l.srttUs = path.srttUs;
    l.rttVarUs = path.rttVarUs;
    l.minRttUs = path.minRttUs;
    l.deliveredPerS = path.deliveredPerS;
    l.lossPermille = path.lossPermille;
    l.lossyAckedBytes = path.lossyAckedBytes;
    l.fullSent = path.fullSent;
}

// 1.5 round trips (or the smoothed one and four deviations, when it varies more) and a margin
// for the client's pass; before a round trip is measured, 250 ms.
uint64_t Outbox::repairTimeout(const Lossy& l) {
    if (l.srttUs <= 0)
        return 250'000;
    const double rto = std::max(1.5 * l.srttUs, l.srttUs + 4 * l.rttVarUs) + 5'000;
    return uint64_t(std::clamp(rto, 10'000.0, 2'000'000.0));
}

uint64_t Outbox::repairTimeoutUs(uint16_t id) const {
    std::lock_guard lock(m_mutex);
    auto it = m_lossy.find(id);
    return it == m_lossy.end() ? 0 : repairTimeout(it->second);
}

// Bytes still on their way: unacknowledged and younger than the repair timeout (older ones are
// taken as lost, so a link that loses everything is offered one window a timeout).
bool Outbox::lossyHeldBack(const Lossy& l, uint64_t now) const {
    const uint64_t timeout = repairTimeout(l);
    int64_t onTheWay = 0;
    for (const SentRect& r : l.unacked)
        if (!r.reliable && now - r.sentUs < timeout)
            onTheWay += r.bytes;
    return onTheWay > std::min(lossyWindow(l), m_maxInFlightBytes);
}

int64_t Outbox::lossyWindow(const Lossy& l) {
    if (l.minRttUs <= 0 || l.deliveredPerS <= 0)
        return kLossyStartBytes;
    const double window = 2.0 * l.deliveredPerS * l.minRttUs * 1e-6;
    return std::clamp(int64_t(window), kLossyMinWindowBytes, kLossyWindowBytes);
}

// Whether `p` goes lossy, decided once it is coded. A full image that fits a lossy message, once
// a round trip is measured (the join's acknowledgement gives the first), to a client that reports
// loss or has not measured it yet: its parity carries it through a lost datagram, where a
// reliable one waits a round trip for ENet's resend. The join's, any before that round trip, and
// any on a link measured clean go reliably: ENet's window paces them, and a lossy one's re-send
// needs the round trip (64 lossy joins at once, re-sent every 250 ms, overflowed a classroom's
// relay). A rectangle after a full image sent lossy that the client has not acknowledged: a
// reliable one could overtake it, and be ignored and never repaired.
bool Outbox::sendsLossy(uint16_t id, PendingImage& p) const {
    auto l = m_lossy.find(id);
    if (p.full) {
        p.lossy = p.message.size() <= kLossyMaxMessageBytes && l != m_lossy.end() &&
                  l->second.srttUs > 0 && (!l->second.lossMeasured() || l->second.lossPermille > 0);
    } else if (p.afterFull && !p.lossy && p.message.size() <= kLossyMaxMessageBytes) {
        p.lossy = l != m_lossy.end() && l->second.fullUnacked();
    }
    return p.lossy;
}

// A full image leaves: lossy, it is kept until acknowledged, to be sent again.
void Outbox::sentFull(uint16_t id, const PendingImage& p, uint64_t now) {
    auto it = m_lossy.find(id);
    if (it == m_lossy.end() || it->second.fullSequence != p.sequence)
        return;
    Lossy& l = it->second;
    l.fullSent = l.fullSent || !p.preview;
    l.fullSentUs = now;
    l.fullRepairs = 0;
    l.fullMessage.clear();
    if (p.lossy) {
        l.fullInFlight = p.inFlight;
        l.fullMessage = p.message;
        l.fullPayload = p.payloadBytes;
        l.fullRaw = p.rawBytes;
    }
}

// A rectangle after a full image has gone, lossy or not: remembered until acknowledged, for
// self-contained ones to carry, the window and the round trip (a reliable one may arrive after a
// newer lossy one, which the client then has).
void Outbox::sentAfterFull(uint16_t id, PendingImage& p, uint64_t now) {
    auto it = m_lossy.find(id);
    if (it == m_lossy.end())
        return;
    Lossy& l = it->second;
    l.unacked.push_back({p.sequence, p.rect, int64_t(p.message.size()), now, p.causeUs, 0, !p.lossy,
                         p.baseSequence != 0});
    if (l.unacked.size() > kMaxUnacked) {
        SentRect& next = l.unacked[1];
        next.rect = unite(l.unacked[0].rect, next.rect);
        next.causeUs = std::min(next.causeUs, l.unacked[0].causeUs);
        next.bytes += l.unacked[0].reliable ? 0 : l.unacked[0].bytes;
        next.repairs = std::max(next.repairs, 1); // times no round trip
        l.unacked.erase(l.unacked.begin());
    }
    l.newestSent = p.sequence;
    if (!p.lossy) {
        l.newest.clear(); // ENet delivers it: nothing to repair
        return;
    }
    l.newest = p.message; // kept for a repair (its pixels are current: a newer change would wait)
    l.newestPayload = p.payloadBytes;
    l.newestRaw = p.rawBytes;
}

// The newest rectangle's pixels are current (a newer change would wait, or have gone), so
// re-sending its bytes repairs it: all before it too when it is self-contained; a chained one
// applies if only it was lost, else the client reports it unusable. The wait grows by one timeout a
// repair, to four: doubling left a rectangle unrepaired for 1.5 s at 5 % loss, where half of all
// 15-fragment rectangles are lost.
void Outbox::takeRepairs(const std::function<bool(uint16_t)>& live, uint64_t now, Taken& taken) {
    for (auto& [id, l] : m_lossy) {
        if (!live(id))
            continue;
        // An unacknowledged lossy full image again (rectangles may wait behind it): after the
        // repair timeout and its own delivery time at the measured rate, twice that each time,
        // and not while ENet still holds much of the client's (a shared link's queue).
        const double deliverUs =
            l.deliveredPerS > 0 ? double(l.fullMessage.size()) * 1e6 / l.deliveredPerS : 0;
        const uint64_t fullTimeout = (repairTimeout(l) + uint64_t(deliverUs))
                                     << std::min(l.fullRepairs, 4);
        if (l.fullUnacked() && now - l.fullSentUs >= fullTimeout && !heldBack(l.fullInFlight)) {
            l.fullSentUs = now;
            ++l.fullRepairs;
            ++m_repairs;
            taken.updates.push_back({id, Sync::Dbi, Channel::ImageLossy, true, l.fullPayload,
                                     l.fullRaw, l.fullMessage, parityLoss(l)});
        }
        if (l.unacked.empty() || m_images.count(id))
            continue;
        SentRect& r = l.unacked.back();
        // ENet delivers a reliable one, and a self-contained one applies; a chained one is
        // unusable after a lost one, and the client's one report of it may be lost too.
        if (r.reliable && !r.chained)
            continue;
        if (now - r.sentUs < repairTimeout(l) * uint64_t(1 + std::min(r.repairs, 3)))
            continue;
        r.sentUs = now;
        ++r.repairs;
        ++m_repairs;
        if (r.reliable) {
            l.repairWanted = true; // the step posts a self-contained one
            continue;
        }
        taken.updates.push_back({id, Sync::Dbi, Channel::ImageLossy, false, l.newestPayload,
                                 l.newestRaw, l.newest, parityLoss(l)});
    }
}

void Outbox::acknowledge(uint16_t id, const ImageAck& ack) {
    const uint64_t now = m_clock();
    std::lock_guard lock(m_mutex);
    auto it = m_lossy.find(id);
    const auto after = [](uint32_t a, uint32_t b) { return int32_t(a - b) > 0; };
    // Only what this server sent this client, for the view it holds: anything else is stale (an
    // old view's, one from before its full image) or forged (a sequence not sent yet).
    if (it == m_lossy.end() || it->second.viewId != ack.viewId || it->second.fullSequence == 0 ||
        after(it->second.fullSequence, ack.sequence) ||
        after(ack.sequence,
              it->second.newestSent ? it->second.newestSent : it->second.fullSequence)) {
        ++m_acksIgnored;
        return;
    }
    Lossy& l = it->second;
    // The first acknowledgement of the join's exact full image, never re-sent, is the first round
    // trip: an upper bound (it includes the image's delivery), for the repair timeout only.
    if (!l.based && l.srttUs <= 0 && l.fullSent && l.fullRepairs == 0 && l.fullSentUs > 0 &&
        now > l.fullSentUs) {
        l.srttUs = double(now - l.fullSentUs);
        l.rttVarUs = l.srttUs / 2;
    }
    l.based = true;
    l.lossyAckedBytes += int64_t(l.fullMessage.size());
    l.fullMessage = {};
    l.fullInFlight.reset();
    l.lossPermille = ack.lossPermille;
    // A rectangle it could not use, chained after one lost and no self-contained one since:
    // the next rectangle posted carries everything not acknowledged.
    if (ack.unusable != 0 && !after(ack.unusable, l.newestSent ? l.newestSent : l.fullSequence) &&
        after(ack.unusable, l.selfContained)) {
        l.repairWanted = true;
        ++m_gapsReported;
    }
    auto acked = l.unacked.begin();
    for (; acked != l.unacked.end() && !after(acked->sequence, ack.sequence); ++acked) {
        if (acked->sequence == ack.sequence && acked->repairs == 0) {
            // One round trip (Karn: never one of a re-sent rectangle), smoothed as TCP does.
            const double sample = double(now - acked->sentUs);
            l.minRttUs = l.minRttUs > 0 ? std::min(l.minRttUs, sample) : sample;
            if (l.srttUs <= 0) {
                l.srttUs = sample;
                l.rttVarUs = sample / 2;
            } else {
                l.rttVarUs = 0.75 * l.rttVarUs + 0.25 * std::abs(l.srttUs - sample);
                l.srttUs = 0.875 * l.srttUs + 0.125 * sample;
            }
        }
    }
    // What the link delivers: lossy bytes acknowledged over the time since the last ack, smoothed.
    int64_t bytes = 0;
    for (auto r = l.unacked.begin(); r != acked; ++r)
        bytes += r->reliable ? 0 : r->bytes;
    l.lossyAckedBytes += bytes;
    if (l.lastAckUs && now > l.lastAckUs && bytes > 0) {
        const double rate = double(bytes) * 1e6 / double(now - l.lastAckUs);
        l.deliveredPerS = l.deliveredPerS > 0 ? 0.8 * l.deliveredPerS + 0.2 * rate : rate;
    }
    l.lastAckUs = now;
    l.unacked.erase(l.unacked.begin(), acked);
}

} // namespace trephine::net
