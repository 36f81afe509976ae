// What a submit asks for, checked before anything large is allocated or any scene is
// unpacked: the protocol, the settings, the frame list, and the limits on live work (per
// client: jobs, scene bytes, samples queued; for everyone: pixels of live films). The
// limits bound memory and keep clients fair. An admitted submit holds its place in them
// while its scene is checked (JobTable::reserve), so racing submits cannot pass together;
// a requeue passes the same limits.
#pragma once

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "server/job_table.h"
#include "server/options.h"

namespace tessera {
// What a live pixel costs the coordinator: its film's sums (docs/performance.md).
constexpr int64_t kFilmBytesPerPixel = int64_t(sizeof(PixelSums));
// The default --max-live-pixels on a machine with `memory_bytes`: 2^27 (5.4 GB of films), or
// as many as half its memory holds if fewer.
inline int64_t live_pixel_default(uint64_t memory_bytes) {
  return std::min<int64_t>(int64_t(1) << 27, int64_t(memory_bytes / 2 / kFilmBytesPerPixel));
}
}  // namespace tessera

namespace tessera {

struct Admission {
  RenderSettings settings;
  std::vector<int> frames;   // empty: a still
  int64_t pixels = 0;        // of one frame
  uint64_t samples = 0;      // of every frame, at most
  uint64_t scene_bytes = 0;  // the bundle's weight on disk (SceneWeight)
};

// Throws RequestError (kInvalidArgument) naming what is wrong.
Admission admit(const v1::SubmitJobRequest& request);
// The limit the job would pass, said for the client ("" when it fits).
std::string over_limit(const Admission& a, const Load& load, const CoordinatorOptions& o, const std::string& owner);

}  // namespace tessera
