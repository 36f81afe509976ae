// What the coordinator counts, for /metrics and the tests. Guarded by its lock.
#pragma once

#include <cstdint>

#include "server/histogram.h"

namespace tessera {

struct CoordinatorCounters {
  uint64_t tasks_dispatched = 0, results_merged = 0, results_duplicate = 0, results_rejected = 0;
  uint64_t leases_expired = 0, leases_released = 0, tasks_failed = 0, samples_merged = 0, jobs_submitted = 0,
           jobs_refused = 0;
  uint64_t images_written = 0, image_errors = 0, checkpoints_written = 0, checkpoint_errors = 0;
  uint64_t jobs_restored = 0, jobs_deleted = 0, jobs_requeued = 0;
  uint64_t checks_issued = 0, checks_passed = 0, check_mismatches = 0, checks_skipped = 0, workers_quarantined = 0,
           tiles_rendered_again = 0;
  uint64_t result_bytes = 0;   // compressed sums of merged results (the bulk of the workers' traffic)
  uint64_t splat_bytes = 0;    // compressed splat records of merged results (light paths)
  uint64_t backup_leases = 0;  // tiles leased a second time at a frame's end
  double merge_seconds = 0;
  Histogram task_seconds;  // merged results' render time, as their workers measured it
};

}  // namespace tessera
