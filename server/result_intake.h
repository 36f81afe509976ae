// Results coming back (SubmitResults), in three steps so that the slow part runs without
// the coordinator's lock: screen() under the lock (is each result's task known, answered by
// its lease's holder, still wanted?), decode() outside it (zstd, and FramePlan::check's
// per-pixel plausibility), merge() under the lock again for the whole batch (each looked at
// again: another copy may have been merged meanwhile). The first result for a (tile, pass)
// wins, even from an expired lease (the bits are the same); later copies are duplicates.
// Results of verification tasks are set aside for the Verifier.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "server/verifier.h"

namespace tessera {

// A result's tile sums, for a tile of `pixels` pixels; throws WireError for any mismatch.
std::vector<PixelSums> result_sums(const v1::TaskResult& result, size_t pixels);

class ResultIntake {
 public:
  struct Parts {
    JobTable& jobs;
    LeaseTable& leases;
    Leasing& leasing;
    WorkerRegistry& workers;
    Verifier& verifier;
    JobLifecycle& lifecycle;
    const Snapshotter& snapshots;
    CoordinatorCounters& counters;
  };
  explicit ResultIntake(Parts parts) : p_(parts) {}

  // What a task's splats may hold: a record for each of its passes (sample ranges), on
  // `tile`'s pixels.
  static SplatLimits splat_limits(const RenderSettings& settings, const Rect& tile,
                                  const std::vector<std::pair<uint32_t, uint32_t>>& passes);
  // A result's splats, decoded within `limits`. A frame the coordinator found to trace light
  // paths (settings: light_tracer on, resolved at submit) must send them, any other none;
  // WireError otherwise.
  static std::vector<SplatRecord> result_splats(const v1::TaskResult& result, RenderSettings::LightTracer mode,
                                                const SplatLimits& limits);

  struct Incoming {
    size_t index = 0;  // in the batch
    size_t pixels = 0;
    uint32_t planes = 1;  // of sums (RenderSettings::sum_planes())
    uint32_t pass_len = 0;
    bool aovs_wanted = false;         // the job has AOVs (settings.aovs)
    std::optional<CheckedSums> sums;  // decoded and plausible
    std::vector<AovSums> aovs;        // likewise, when wanted
    SplatLimits splat_limits;         // what its splats may be (a frame tracing light paths)
    RenderSettings::LightTracer light_tracer = RenderSettings::LightTracer::kOff;  // the job's
    std::vector<SplatRecord> splats;                                               // decoded: one per pass, or none
    bool splats_over_cap = false;  // its splats passed the task's cap (SplatsOverCap): its run was too long
    std::string refused;           // why its sums, AOVs or splats did not decode (WireError), if so
  };
  struct Batch {
    std::vector<const v1::TaskResult*> results;
    std::vector<v1::ResultAck> acks;               // one each, in order
    std::vector<Incoming> incoming;                // to decode and merge
    std::vector<std::pair<size_t, Lease>> checks;  // results of verification tasks
  };
  Batch screen(const std::vector<const v1::TaskResult*>& results);
  // The batch's incoming results are decoded and merged a slice at a time, [first, last),
  // and each slice's decoded buffers freed after its merge: a batch's copies of one result,
  // or its many small results whose splats decode to tens of megabytes each, made the
  // coordinator hold gigabytes decoded at once (1.9 GB from 445 KB sent).
  static constexpr uint64_t kDecodedBytesPerSlice = uint64_t(128) << 20;
  // The end of the slice that starts at `first`: results while their decoded bytes at most
  // (decoded_bytes) stay within kDecodedBytesPerSlice, one at least.
  static size_t slice_end(const Batch& batch, size_t first);
  static uint64_t decoded_bytes(const Batch& batch, const Incoming& in);
  static void decode(Batch& batch, size_t first, size_t last);
  void merge(Batch& batch, size_t first, size_t last, double now, Effects& fx);
  static void free_decoded(Batch& batch, size_t first, size_t last);

  // What a refused result's ack, its task.failed event and the log say: "result refused: WHY"
  // (a task's result here, a check's in Coordinator::check_result).
  static std::string refusal(const std::string& why) { return "result refused: " + why; }

 private:
  // The result's lease if it is known, from its holder, and still wanted (counting and
  // acknowledging duplicates and strangers' results); nullopt otherwise.
  std::optional<Lease> wanted(const v1::TaskResult& result, v1::ResultAck& ack);
  // Whether the job still wants the lease's (tile, pass) from it (wanted() and refuse()).
  static bool still_wanted(const Lease& lease, const Job& job);
  // A result whose run of passes carried more splats than a result may (SplatsOverCap):
  // its job's runs are halved (Job::max_run) and its lease ends with the run ready again.
  // False (nothing done) for a single pass or a lease no longer its holder's.
  bool shorten_runs(const v1::TaskResult& result, double now, Effects& fx);
  // A result its task's holder sent that does not decode (`why`): the task failed on that
  // worker (JobLifecycle::task_failed: a task.failed event naming why; tasks failed on two
  // workers fail the job), once a lease. The lease still waits for a good result until it
  // expires (the tile is not handed straight back to a worker that just failed it). Before,
  // nothing was said or counted: a job whose every worker sent such results (a version
  // skew, a bug) went round for ever in silence.
  void refuse(const v1::TaskResult& result, const std::string& why, double now, Effects& fx);

  Parts p_;
};

}  // namespace tessera
