// A worker's bandwidth budget: whether its link carries its results as fast as its threads
// render them, and if not, how many passes of a tile one task should hold so that it does
// (a run of passes, FramePlan::take: one result for several passes, the same bits).
//
// A result's bytes depend on its pixels, not its samples (sums, compressed), so a run of k
// passes costs a k-th of the bytes a sample. The link's rate shows only while the link is
// the limit: then SubmitResults calls take clearly longer than the link's shortest round
// trip and the coordinator's time over them (ResultAcks.held_ms) together (their bytes
// queue at the narrow link; a request for work queued behind them takes longer too, so the
// smoothed round trip would hide it), and the link is busy throughout, so answers come as
// fast as it carries the calls' bytes, which measures its rate (as BBR measures delivery). Results are budgeted to use
// at most half of it (room for the link's own ups and downs and the requests for work). Runs only grow: a link that
// carried a worker's results once at this size keeps doing so. A pure rule over the calls it is told of, so that tests
// state it with numbers.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>

#include "worker/lookahead.h"

namespace tessera::worker {

class UploadBudget {
 public:
  static constexpr uint32_t kMaxPasses = Lookahead::kMaxPasses;  // the coordinator's bound too
  static constexpr size_t kCalls = 16;                           // recent calls looked at
  static constexpr size_t kMinCalls = 4;                         // before any judgement
  // Seconds beyond a round trip that count as slowed: more than a loaded machine delays a
  // call on loopback, far less than a queue at a narrow link builds.
  static constexpr double kMinQueueing = 0.1;
  static constexpr double kShare = 0.5;  // of the link's rate, for results

  // One SubmitResults call: when it began and was answered (steady seconds), the
  // coordinator's time over it, its results' compressed bytes, their samples, the thread-
  // seconds their rendering took, and those samples' bytes had they come a pass a task
  // (sums' bytes x passes in each result's run, plus its splats': a record a pass either way).
  struct Call {
    double start = 0, end = 0, held = 0;
    uint64_t bytes = 0;
    double samples = 0, busy = 0;
    double single_pass_bytes = 0;
  };

  // `threads`: the worker's render threads. `fixed` > 0: always that many passes a task
  // (--passes-per-task); 0: as the link needs.
  UploadBudget(int threads, uint32_t fixed)
      : threads_(std::max(1, threads)), passes_(fixed > 0 ? std::min(fixed, kMaxPasses) : 1), fixed_(fixed > 0) {}

  // A call answered; `round_trip` is the link's shortest (0 if unknown).
  void note(const Call& call, double round_trip) {
    calls_.push_back(call);
    if (calls_.size() > kCalls) calls_.pop_front();
    if (fixed_ || calls_.size() < kMinCalls) return;
    // The link's rate from the calls it slowed: while it is busy, answers come as fast as
    // it carries the calls' bytes, so the bytes of all but the first answered over the time
    // from the first answer to the last. The results' rate from all the calls: their
    // samples over their render time (the same tiles, so a frame's fast and slow parts
    // weigh alike in both).
    size_t slowed = 0;
    double first = 0, last = 0, first_bytes = 0, slowed_bytes = 0, samples = 0, busy = 0, single = 0;
    for (const Call& c : calls_) {
      samples += c.samples;
      busy += c.busy;
      single += c.single_pass_bytes;
      if (c.end - c.start - c.held <= round_trip + std::max(kMinQueueing, 0.5 * round_trip)) continue;
      if (slowed++ == 0 || c.end < first) {
        first = c.end;
        first_bytes = double(c.bytes);
      }
      last = std::max(last, c.end);
      slowed_bytes += double(c.bytes);
    }
    if (2 * slowed < calls_.size() || last <= first || samples <= 0 || busy <= 0) return;  // not the link's limit
    rate_ = (slowed_bytes - first_bytes) / (last - first);
    const double render_rate = samples / busy * threads_;        // samples a second
    const double results_rate = render_rate * single / samples;  // bytes a second, a pass a task
    passes_ = uint32_t(std::clamp<double>(std::ceil(results_rate / (kShare * rate_)), passes_, kMaxPasses));
  }

  uint32_t passes_per_task() const { return passes_; }
  bool fixed() const { return fixed_; }
  double link_rate() const { return rate_; }  // bytes a second, as last measured; 0: not limited yet

 private:
  std::deque<Call> calls_;
  int threads_;
  uint32_t passes_;
  bool fixed_;
  double rate_ = 0;
};

}  // namespace tessera::worker
