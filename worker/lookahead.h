// How much work a worker keeps leased: its window of work in flight, sized like a TCP
// window from the bandwidth-delay product. Enough that its threads never run dry, plus what
// they get through in `seconds` and in two of the link's round trips at the measured speed
// (one for the request on its way, one of margin for faster tiles), and never more leases
// than the coordinator allows this worker. A pure rule over the queue's load, so that tests
// can state it with numbers; nothing to tune for a far or near coordinator.
//
// A far worker also takes its tasks as runs of a tile's passes (FramePlan::take): a tile's
// next pass is leased only once its last one is merged, so each pass of a tile costs a far
// worker a round trip, hidden behind other tiles until the frame's last ones. Runs long
// enough that a task renders for at least a round trip leave the frame's end no chain of
// round trips to wait through.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace tessera::worker {

// The lease cap until the coordinator names its bound (RegisterResponse.max_leases), and
// with coordinators from before that field.
constexpr size_t kDefaultMaxLeases = 64;

// What the worker holds and has queued, how fast it renders and how far away the
// coordinator is.
struct QueueLoad {
  size_t held = 0;                        // leased and not yet submitted
  uint64_t queued_rows = 0;               // rows not yet handed to a render thread
  double queued_samples = 0;              // camera samples in those rows
  double samples_per_thread_second = 0;   // measured (smoothed); 0 until a task finished
  double round_trip = 0;                  // seconds from asking for work to having it (smoothed); 0: unknown
  size_t max_leases = kDefaultMaxLeases;  // the coordinator's bound (RegisterResponse), or --max-leases if lower
  uint32_t passes_per_task = 1;           // runs of passes the link needs (upload_budget.h)
  double pass_samples = 0;                // camera samples in a task's pass (smoothed); 0: unknown
  bool passes_fixed = false;              // --passes-per-task: passes_per_task and nothing else
};

// A GetTask request's size: up to max_tasks tasks, stopping at max_samples (0: no limit),
// each a run of up to max_passes passes of a tile.
struct LeaseRequest {
  uint32_t max_tasks = 0;
  uint64_t max_samples = 0;
  uint32_t max_passes = 1;
};

struct Lookahead {
  // Nearer than this (a LAN), a tile's passes come one a task: the progressive image stays
  // fine-grained and the chain costs nothing worth a run.
  static constexpr double kFarRoundTrip = 0.005;
  static constexpr uint32_t kMaxPasses = 64;  // the coordinator's bound too

  int threads = 1;
  double seconds = 0.3;  // --lookahead-seconds

  // Samples the window holds once the speed is known.
  double window_samples(const QueueLoad& load) const {
    return load.samples_per_thread_second * threads * (seconds + 2 * load.round_trip);
  }
  // The queue below which to ask for more: half the lookahead (refilling at half, up to
  // all of it, makes fewer and larger requests) and two whole round trips, so the answer
  // arrives before the queue runs out even when the queued tiles render three times
  // faster than the measured speed (tiles of one frame differ that much).
  double refill_samples(const QueueLoad& load) const {
    return load.samples_per_thread_second * threads * (0.5 * seconds + 2 * load.round_trip);
  }
  // Whether to ask for more now: the threads are about to run dry (fewer than two rows per
  // thread queued), or, once the speed is known, the queue is below the refill point.
  bool wants_more(const QueueLoad& load) const {
    if (load.held >= load.max_leases) return false;
    if (load.queued_rows < 2 * uint64_t(threads)) return true;
    const double refill = refill_samples(load);
    return refill > 0 && load.queued_samples < refill;
  }
  // Passes a task should hold for the link's round trip (1 when near or unmeasured): enough
  // that the worker's threads render a task for a round trip.
  uint32_t chain_passes(const QueueLoad& load) const {
    if (load.round_trip < kFarRoundTrip || load.pass_samples <= 0 || load.samples_per_thread_second <= 0) return 1;
    const double pass_seconds = load.pass_samples / (load.samples_per_thread_second * threads);
    return uint32_t(std::clamp(std::ceil(load.round_trip / pass_seconds), 1.0, double(kMaxPasses)));
  }
  // The window less what is queued; two tasks until there is a measurement. Only when
  // wants_more().
  LeaseRequest request(const QueueLoad& load) const {
    const double window = window_samples(load);
    const uint32_t room = uint32_t(std::min<size_t>(load.max_leases - load.held, UINT32_MAX));
    const uint32_t passes =
        load.passes_fixed ? load.passes_per_task : std::max(load.passes_per_task, chain_passes(load));
    if (window <= 0) return {std::min(room, 2u), 0, passes};
    return {room, uint64_t(std::max(1.0, window - load.queued_samples)), passes};
  }
};

}  // namespace tessera::worker
