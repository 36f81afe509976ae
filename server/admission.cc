#include "server/admission.h"

#include <cmath>
#include <set>

#include "core/render/aov.h"
#include "core/render/frames.h"
#include "core/util/saturating.h"
#include "server/request_error.h"
#include "server/scene_store.h"

namespace tessera {

Admission admit(const v1::SubmitJobRequest& req) {
  auto refuse = [](const std::string& why) { return RequestError(RequestError::Code::kInvalidArgument, why); };
  if (req.version() != kProtocolVersion)
    throw refuse("protocol version " + std::to_string(req.version()) + " not supported (this coordinator speaks " +
                 std::to_string(kProtocolVersion) + ")");
  Admission a;
  try {
    a.settings = from_proto(req.settings());
  } catch (const WireError& e) {
    throw refuse(e.what());
  }
  // (Kept in memory, in the database row and in every status: bounded like a worker's name.)
  if (req.name().size() > kMaxJobNameBytes)
    throw refuse("a job name of " + std::to_string(req.name().size()) + " bytes; at most " +
                 std::to_string(kMaxJobNameBytes));
  if (!req.upload_id().empty() && (req.files_size() > 0 || !req.main_file().empty()))
    throw refuse("a job's scene is its files or an upload (upload_id), not both");
  // A task's result goes to the coordinator in one call: its largest tile's sums (and AOV
  // sums) must fit a call, or no worker could send them (a 4096-pixel tile's did not: the
  // job failed only once two workers had rendered and released a task).
  const Rect window = a.settings.effective_window();
  const uint64_t tile_area = uint64_t(std::min(a.settings.tile_size, window.w)) *
                             uint64_t(std::min(a.settings.tile_size, window.h)),
                 per_pixel = a.settings.sum_planes() * kBytesPerPixel + (a.settings.aovs ? sizeof(AovSums) : 0);
  if (tile_area * per_pixel > kMaxResultBytes) {
    const int fits = int(std::sqrt(double(kMaxResultBytes / per_pixel)));
    throw refuse("--tile " + std::to_string(a.settings.tile_size) + ": a task's sums take up to " +
                 std::to_string((tile_area * per_pixel) >> 20) + " MiB, over the " +
                 std::to_string(kMaxResultBytes >> 20) + " MiB a result may carry to the coordinator: give --tile " +
                 std::to_string(fits) + " or less");
  }
  a.frames.assign(req.frames().begin(), req.frames().end());
  if (!a.frames.empty()) {
    if (a.settings.frame) throw refuse("a sequence's settings have no frame number: its frames are listed in frames");
    if (a.frames.size() > kMaxFrames)
      throw refuse(std::to_string(a.frames.size()) + " frames; at most " + std::to_string(kMaxFrames) + " in one job");
    std::set<int> seen;
    for (const int f : a.frames) {
      if (f < -RenderSettings::kMaxFrame || f > RenderSettings::kMaxFrame)
        throw refuse("frame " + std::to_string(f) + " out of range (at most " +
                     std::to_string(RenderSettings::kMaxFrame) + " either side of 0)");
      if (!seen.insert(f).second) throw refuse("frame " + std::to_string(f) + " given twice");
    }
  }
  a.pixels = live_pixels_of(a.settings);
  // Samples are the window's pixels' (not the film's weight, which counts AOV sums, half-
  // buffers and splats as pixels too).
  a.samples = saturating_mul(uint64_t(a.settings.effective_window().area()) * uint64_t(a.settings.spp),
                             std::max<uint64_t>(1, a.frames.size()));  // (2^27 pixels x 2^24 spp fit)
  a.scene_bytes = bundle_bytes(req.files());                           // an upload's: SceneUploads::bytes
  return a;
}

std::string over_limit(const Admission& a, const Load& load, const CoordinatorOptions& o, const std::string& owner) {
  const std::string who = owner.empty() ? std::string("this coordinator") : "client '" + owner + "'";
  if (load.client_scene_bytes + a.scene_bytes > o.max_scene_bytes_per_client)
    return who + "'s live jobs hold " + std::to_string(load.client_scene_bytes) + " scene bytes; this job's " +
           std::to_string(a.scene_bytes) + " would pass the limit of " + std::to_string(o.max_scene_bytes_per_client) +
           " (--max-scene-bytes-per-client)";
  if (saturating_add(load.client_samples_remaining, a.samples) > o.max_queued_samples_per_client)
    return who + " has " + std::to_string(load.client_samples_remaining) + " samples queued; this job's " +
           std::to_string(a.samples) + " would pass the limit of " + std::to_string(o.max_queued_samples_per_client) +
           " (--max-queued-samples-per-client)";
  if (load.client_jobs >= o.max_jobs_per_client)
    return who + " has " + std::to_string(load.client_jobs) + " live jobs, the most allowed (--max-jobs-per-client)";
  if (a.pixels > o.max_live_pixels)  // never, however empty the farm: say what it would take
    return "a frame of " + std::to_string(a.pixels) + " pixels needs " +
           std::to_string(a.pixels * kFilmBytesPerPixel >> 20) + " MiB of film (" + std::to_string(kFilmBytesPerPixel) +
           " bytes a pixel); this coordinator holds at most " + std::to_string(o.max_live_pixels) + " live pixels (" +
           std::to_string(o.max_live_pixels * kFilmBytesPerPixel >> 20) +
           " MiB, --max-live-pixels): render it in parts (-p) or raise the limit on a machine with the memory";
  if (load.live_pixels + a.pixels > o.max_live_pixels)
    return "live frames hold " + std::to_string(load.live_pixels) + " pixels; this job's " + std::to_string(a.pixels) +
           " would pass the limit of " + std::to_string(o.max_live_pixels) + " (--max-live-pixels); try again later";
  return "";
}

}  // namespace tessera
