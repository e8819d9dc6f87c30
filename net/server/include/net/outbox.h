// The session server's outbox, between the simulation step (which posts) and the network thread
// (which takes): per client at most one image and one volume update wait, and a newer change
// merges into the waiting one, so a region is never queued twice and the newest pixels or voxels
// win. It keeps each zstd client's copy of its DBI (the shadow predicted updates are coded
// against) and holds a client back while ENet still holds more than maxInFlightBytes of its
// updates. Full images go reliably, or lossy once a round trip is measured to a client that has
// not measured a clean link (sendsLossy); the rectangles after one go lossy (Channel::ImageLossy,
// with parity for the loss the client reports, or 1 % before its figure counts), in one of two
// forms. Chained: only its own pixels, predicted against the picture the client holds once the
// one before it arrives (ImageUpdate::baseSequence), as small as a reliable update.
// Self-contained: every rectangle the client has not acknowledged, at current pixels. Rectangles
// are chained; when the client reports one it could not use (ImageAck::unusable), a
// self-contained one repairs the gap at once. The newest image is re-sent while unacknowledged
// past a timeout, never a retransmission in order. Posting and taking may run on two threads, and
// acknowledgements arrive on the taking one; everything else is the posting thread's. No ENet
// here: tests post and take in one thread, with a clock passed in.
#pragma once

#include "libsim/box.h"
#include "libsim/camera.h"
#include "libsim/dbi.h"
#include "libsim/dirty_rect.h"
#include "libsim/volume.h"
#include "net/enet_host.h"
#include "net/executor.h"
#include "net/protocol.h"
#include "net/server_report.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

namespace trephine::net {

// Microseconds on the server's clock (steadyNowUs in the server; tests pass their own).
using ServerClock = std::function<uint64_t()>;

// The stage times an image update carries (microseconds).
struct ImageTiming {
    uint32_t erodeUs = 0, renderUs = 0, gridUs = 0;
};

// A change of voxels for a volume client: a box (or the whole volume) and the oldest cause.
struct VolumeChange {
    Box3i box;
    bool full = false, materials = false;
    uint64_t causeUs = 0;
    uint32_t erodeUs = 0; // every batch's erosion it carries
};

class Outbox {
public:
    // An update ready for the network: its message and what the report counts of it.
    struct Ready {
        uint16_t client = 0;
        Sync mode = Sync::Dbi;            // Dbi: an ImageUpdate; Volume: a VolumeUpdate
        Channel channel = Channel::Image; // Image, ImageLossy or Volume
        bool full = false;
        uint32_t payloadBytes = 0, rawBytes = 0;
        std::vector<uint8_t> message;
        uint32_t lossPermille = 0; // ImageLossy: the loss its parity is for (Host::send)
    };
    struct Taken {
        std::vector<Ready> updates; // images first, each kind by client id
        // Volume clients whose whole volume fits no message in their codec: to be sent away
        // (RefuseReason::VolumeTooLarge).
        std::vector<uint16_t> refused;
    };

    // `wake` is called after each post (the server wakes its network thread with it).
    Outbox(int64_t maxInFlightBytes, ReportBook& book, ServerClock clock,
           std::function<void()> wake = {});
    ~Outbox();
    Outbox(const Outbox&) = delete;
    Outbox& operator=(const Outbox&) = delete;

    // [Posting thread, before any post] Full images of at least `minPixels` (0: none) are coded
    // on `coder` (the server's runner gives a worker thread of low priority), from a copy taken
    // at the post, so the posting thread does not stop for the whole frame's coding (a 2048 x
    // 2048 view: ~140 ms on the 2-core VM). A change posted meanwhile waits behind that image as
    // a rectangle of its own. Until this is called, images are coded inline.
    void codeFullImagesApart(int64_t minPixels, Executor& coder) {
        m_apartPixels = minPixels;
        m_coder = &coder;
    }
    // Whether a full image of `pixels` is coded apart (from a copy).
    bool codesApart(int64_t pixels) const { return m_apartPixels > 0 && pixels >= m_apartPixels; }
    // [Posting thread] Waits until the coder has coded everything posted so far.
    void finishCoding();

    // [Posting thread] A client joins with the counter of its bytes ENet holds (Host::send),
    // its image codec and its volume codec; its view id starts at 0.
    void join(uint16_t id, Host::InFlight inFlight, Codec codec, Codec volumeCodec);
    void leave(uint16_t id);
    // The client's view changed: its waiting image belongs to the view it left and is dropped.
    void viewChanged(uint16_t id, uint32_t viewId);
    // The client's sync mode (or volume codec) changed: nothing it waits for in the other mode
    // is wanted, and its next DBI is a full one.
    void modeChanged(uint16_t id, Sync mode, Codec volumeCodec);

    // Queues `rect` of `frame` (the view seen by `camera`) for client `id`, merged with its
    // waiting image of the same view: the union is taken from the frame now. A waiting rectangle
    // outside the frame is never merged: the client gets the whole frame. `othersFollow`: more
    // clients of this view are posted next, so the coding is kept for them (Coded).
    void postImage(uint16_t id, const Camera& camera, const Dbi& frame, PixelRect rect, bool full,
                   uint64_t causeUs, ImageTiming timing, bool othersFollow = false);
    // A full image of `pixels` (a copy of the view's frame the caller made, see buffer()), coded
    // apart like the large ones postImage copies itself.
    // `preview`: a new view's first picture, `pixels` and `camera` its half-size render
    // (previewCamera, ImageUpdate::preview); its exact full image follows.
    void postFullImage(uint16_t id, const Camera& camera, Dbi pixels, uint64_t causeUs,
                       bool preview = false);
    // [Posting thread] A frame of that size for postFullImage, its pixels to be written whole by
    // the caller: the coder's last buffer when it fits (its memory already mapped), else a new
    // one left unfilled.
    Dbi buffer(int width, int height);
    // A volume client's change (or none, to retry one noted earlier). Posted, merged with its
    // waiting update, unless the client is held back with one waiting: then it is only noted and
    // coded once, when the waiting one has gone. A box too large for a message goes as the whole
    // volume; a whole volume too large is a refusal (Taken::refused).
    void offerVolume(uint16_t id, const Volume& volume, std::optional<VolumeChange> change);
    // Offers again every change noted for a held-back client.
    void offerNoted(const Volume& volume);

    // [Network thread] Takes every waiting update except those of live clients held back (over
    // maxInFlightBytes in ENet's hands, or lossy bytes unacknowledged within the repair timeout
    // over kLossyWindowBytes); those of clients not `live` (gone, or being sent away) are
    // dropped. With them, the repairs due: a live client's newest lossy rectangle again when it
    // is still unacknowledged past the timeout (one timeout more a repair of it, up to four) and
    // nothing newer waits; a reliable chained one left so asks the step (postRepairs) for a
    // self-contained one.
    Taken take(const std::function<bool(uint16_t)>& live);
    // [Network thread] Client `id` has applied image `sequence` of its view (ImageAck): what it
    // acknowledges is forgotten, and its round trip times the repairs. An ack of another view, of
    // an image older than the client's full image or newer than any sent is ignored.
    void acknowledge(uint16_t id, const ImageAck& ack);
    // The most lossy bytes a client may have unacknowledged (within the repair timeout) before
    // its next rectangle waits, merged with the ones after it: twice what the acknowledgements
    // say the link delivers in its shortest round trip, within these bounds (the upper one a
    // round trip at 20 Mbit/s and 100 ms), so a slow link queues little in front of tool states
    // and force models; kLossyStartBytes until both are measured. The lower bound is a few
    // datagrams: every client's floor waits on a shared link (64 x 32 KiB queued 170 ms there).
    static constexpr int64_t kLossyWindowBytes = 256 * 1024;
    static constexpr int64_t kLossyMinWindowBytes = 8 * 1024, kLossyStartBytes = 64 * 1024;
    // The largest image sent lossy (~100 datagrams, four stripes each lost at most once in a
    // thousand at the parity for the client's loss); a larger rectangle (a large view's union, a
    // raw client) goes reliably on Channel::Image, still naming its full image, and is never
    // repaired, and a larger full image goes reliably.
    static constexpr size_t kLossyMaxMessageBytes = 128 * 1024;
    // The loss parity is sized for before the client's figure counts (Lossy::lossMeasured()): 1 %,
    // a long link's; a LAN's costs a stripe a few fragments for its first ~200 datagrams.
    static constexpr uint32_t kAssumedLossPermille = 10;
    static constexpr int64_t kLossMeasuredBytes = 256 * 1024;
    // Unacknowledged rectangles kept per client; past it the oldest two merge (a client that
    // never acknowledges costs a bounded list).
    static constexpr size_t kMaxUnacked = 32;
    // [Posting thread] Clients that reported a lost rectangle and wait for no image: each needs a
    // rectangle posted (an empty one will do: it carries what they have not acknowledged).
    std::vector<uint16_t> repairsWanted() const;
    // [Any thread] Repairs sent so far, and acknowledgements ignored as not this client's.
    uint64_t repairs() const { return m_repairs.load(); }
    uint64_t acksIgnored() const { return m_acksIgnored.load(); }
    // [Any thread] Lost rectangles clients reported (ImageAck::unusable), each asking a repair.
    uint64_t gapsReported() const { return m_gapsReported.load(); }
    // [Any thread] The timeout after which client `id`'s unacknowledged rectangle is re-sent.
    uint64_t repairTimeoutUs(uint16_t id) const;

    // [Either thread, once the other has stopped] Forgets every waiting update and noted change:
    // nobody will take them (the server has stopped).
    void clear();

    // [Any thread] Nothing waits and no change is noted.
    bool empty() const;
    // [Posting thread] What client `id` holds once its posted images arrive (empty unless zstd).
    const Dbi* shadow(uint16_t id) const;

private:
    // An image waiting for the network. `undo` holds the shadow's pixels of `rect` from before
    // it, put back if it is merged into a newer one before it leaves (the client never saw it).
    struct PendingImage {
        uint32_t viewId = 0;
        PixelRect rect;
        bool full = false;
        uint64_t causeUs = 0; // the oldest cause merged in: latency is never under-reported
        uint32_t rawBytes = 0, payloadBytes = 0;
        std::vector<uint8_t> message;
        Dbi undo; // empty when full
        Host::InFlight inFlight;
        uint64_t ticket = 0;    // coded apart: its job's ticket (0: coded at the post)
        bool coding = false;    // coded apart, not yet done: it and what follows it wait
        bool lossy = false;     // a rectangle on Channel::ImageLossy
        bool afterFull = false; // a rectangle naming its full image (lossy or not)
        bool preview = false;   // a new view's half-size first picture (ImageUpdate::preview)
        uint32_t sequence = 0;
        uint32_t baseSequence = 0; // chained: the image it builds on (ImageUpdate::baseSequence)
    };
    // A lossy rectangle sent and not acknowledged.
    struct SentRect {
        uint32_t sequence = 0;
        PixelRect rect;
        int64_t bytes = 0;
        uint64_t sentUs = 0;
        uint64_t causeUs = 0;
        int repairs = 0;       // re-sent that many times: its acknowledgement times no round trip
        bool reliable = false; // sent on Channel::Image: outside the window, never re-sent
        bool chained = false;  // ImageUpdate::baseSequence set
    };
    // A DBI client's lossy rectangles (under m_mutex: acknowledged on the network thread).
    struct Lossy {
        uint32_t viewId = 0;
        uint32_t fullSequence = 0;     // the full image they build on; 0: none yet, sent reliably
        bool based = false;            // the client has acknowledged that full image or later
        std::vector<SentRect> unacked; // oldest first
        uint32_t newestSent = 0;
        std::vector<uint8_t> newest; // the newest sent rectangle's message: the repair
        uint32_t newestPayload = 0, newestRaw = 0;
        double srttUs = 0, rttVarUs = 0; // 0: no round trip measured yet
        double minRttUs = 0;             // the shortest round trip measured (0: none)
        double deliveredPerS = 0;        // lossy bytes acknowledged a second, smoothed
        uint32_t lossPermille = 0;       // the loss the client last reported
        // Lossy bytes the client has acknowledged: its figure (smoothed over ~256 datagrams from
        // zero) counts from kLossMeasuredBytes on; until then parity is for kAssumedLossPermille.
        int64_t lossyAckedBytes = 0;
        bool lossMeasured() const { return lossyAckedBytes >= kLossMeasuredBytes; }
        bool fullSent = false; // an exact full image has gone: its acknowledgement is a round trip
        // The full image sent lossy and not yet acknowledged (empty when none): re-sent past the
        // repair timeout.
        std::vector<uint8_t> fullMessage;
        Host::InFlight fullInFlight; // the client's bytes in ENet's hands: no re-send while held
        uint32_t fullPayload = 0, fullRaw = 0;
        uint64_t fullSentUs = 0;
        int fullRepairs = 0;
        uint64_t lastAckUs = 0;
        bool repairWanted = false;  // since then no self-contained rectangle has been posted
        uint32_t selfContained = 0; // the newest self-contained rectangle posted
        bool fullUnacked() const { return !based && !fullMessage.empty(); }
    };
    // What a lossy rectangle posted now must carry, read under m_mutex.
    struct LossyBase {
        uint32_t fullSequence = 0;
        PixelRect unacked;                     // the union of the rectangles not acknowledged
        uint64_t unackedCauseUs = 0;           // their oldest cause
        bool chain = false;                    // no loss reported lately: rectangles are chained
        bool based = false;                    // the client has acknowledged its full image
        std::vector<uint32_t> reliableUnacked; // rectangles sent reliably, not acknowledged
    };
    // A full image for the coder thread: its message but the payload, and the pixels.
    struct CodingJob {
        uint16_t client = 0;
        uint64_t ticket = 0;
        ImageUpdate update;
        Dbi pixels;
        Camera camera;
    };
    struct PendingVolume {
        VolumeChange change;
        uint32_t rawBytes = 0, payloadBytes = 0;
        std::vector<uint8_t> message;
        Host::InFlight inFlight;
    };
    // A client as the outbox sees it (posting thread only).
    struct Client {
        Host::InFlight inFlight;
        Codec codec = Codec::Raw;
        Codec volumeCodec = Codec::Raw;
        uint32_t viewId = 0;
        Dbi shadow;
        uint32_t lastPosted = 0; // the newest image posted (a chained rectangle builds on it)
        std::optional<VolumeChange> noted;
    };

    // The newest coding kept for the clients of a view that follow: one whose copy holds the
    // same pixels there gets its payload as it is (a classroom's 64 watchers share 16 views).
    struct Coded {
        Camera camera;
        Codec codec = Codec::Raw;
        bool predicted = false;
        Dbi pixels, base; // the rectangle, and the client's copy of it (predicted only)
        uint32_t baseHash = 0, rawBytes = 0;
        std::vector<uint8_t> payload;
    };

    bool heldBack(const Host::InFlight& inFlight) const;
    void post(uint16_t id, const Camera& camera, const Dbi& frame, PixelRect rect, bool full,
              uint64_t causeUs, ImageTiming timing, Dbi* owned, bool preview = false,
              bool othersFollow = false);
    bool postVolume(uint16_t id, const Client& c, const Volume& volume, VolumeChange change);
    void postVolumeOrRefuse(uint16_t id, const Client& c, const Volume& volume,
                            const VolumeChange& change);
    void countNoted();
    std::optional<PendingImage> takeMergeable(uint16_t id, uint32_t viewId, bool full,
                                              uint64_t& causeUs, LossyBase& base);
    Dbi encodeInto(ImageUpdate& u, const Client& c, const Dbi& frame, const Dbi& pixels,
                   const Camera& camera, bool predictable, bool keep);
    bool reuseCoding(ImageUpdate& u, const Camera& camera, Codec codec, const Dbi& pixels,
                     const Dbi& base);
    void postedSelfContained(uint16_t id, uint32_t sequence);
    static uint32_t chainOn(const Client& c, const LossyBase& base, const PendingImage* merged);
    void postApart(uint16_t id, Client& c, const Camera& camera, const Dbi& frame, Dbi* owned,
                   ImageUpdate u);
    // Under m_mutex:
    void resetLossy(uint16_t id, uint32_t viewId, uint32_t fullSequence);
    void stampTimes(ImageUpdate& u, ImageTiming timing, uint64_t codedFromUs);
    bool lossyHeldBack(const Lossy& l, uint64_t now) const;
    static int64_t lossyWindow(const Lossy& l);
    static uint32_t parityLoss(const Lossy& l) {
        return l.lossMeasured() ? l.lossPermille : kAssumedLossPermille;
    }
    static uint64_t repairTimeout(const Lossy& l);
    void sentAfterFull(uint16_t id, PendingImage& p, uint64_t now);
    void sentFull(uint16_t id, const PendingImage& p, uint64_t now);
    bool sendsLossy(uint16_t id, PendingImage& p) const;
    void takeRepairs(const std::function<bool(uint16_t)>& live, uint64_t now, Taken& taken);
    void codeApart(uint16_t id, CodingJob job);
    void code(CodingJob job);

    int64_t m_maxInFlightBytes;
    ReportBook& m_book;
    ServerClock m_clock;
    std::function<void()> m_wake;
    std::map<uint16_t, Client> m_clients;
    Coded m_coded;
    uint32_t m_sequence = 0; // image and volume updates share one sequence
    std::atomic<int> m_noted{0};

    mutable std::mutex m_mutex; // the waiting updates, between the two threads
    // Per client its waiting images, oldest first: at most a full image coded apart and the
    // rectangle posted after it.
    std::map<uint16_t, std::vector<PendingImage>> m_images;
    std::map<uint16_t, PendingVolume> m_volumes;
    std::vector<uint16_t> m_refused;
    std::map<uint16_t, Lossy> m_lossy;
    std::atomic<uint64_t> m_repairs{0}, m_acksIgnored{0}, m_gapsReported{0};

    // Where full images are coded apart; the tickets and the spare buffer are under m_mutex.
    int64_t m_apartPixels = 0;
    InlineExecutor m_inline;
    Executor* m_coder = &m_inline;
    uint64_t m_tickets = 0;
    Dbi m_spare; // the pixels of the last job, a buffer for the next
};

} // namespace trephine::net
