// The core's types on the wire: render settings, rectangles and tile sums. Shared by the
// coordinator, the worker and the CLI. Scene bundles are in scene_bundle.h.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "core/render/aov.h"
#include "core/render/film.h"
#include "core/render/settings.h"
#include "core/render/splats.h"
#include "tessera.grpc.pb.h"

namespace tessera {

// Version 2: tile size, noise target and the estimator switches moved into RenderSettings.
// Version 3: tile sums in byte planes.
// Version 4: Image.final (a client writes no image of an ended job that is not final).
// Version 5: scenes stream in pieces (UploadScene, FetchSceneChunks instead of FetchScene).
// Version 6: images stream in pieces (FetchImageChunks); farm EXRs ZIP-compressed; an end
// is reported only once durable.
// Version 7: a worker's requests carry the secret its registration gave (worker_secret).
// Version 8: AOVs (RenderSettings.aovs; a worker sends TaskResult.aovs_zstd for a job with
// them: one before it would not, so it is refused at registration).
// Version 9: half-buffers (the kAovHalves bit of RenderSettings.aovs: a task's sums, its
// result's and a run's base, are two planes) and RenderSettings.denoise.
// Version 10: splats' squared luminance in 2^-32 units (was 2^-12: core/render/splats.h).
// Version 11: which camera samples trace light paths (LightTracer::traces: every pixel's
// now reach both half-buffers), so a version-10 worker's splats differ from a local render's.
constexpr uint32_t kProtocolVersion = 11;
constexpr size_t kBytesPerPixel = 36;  // r, g, b, lum2 (float64) + n (uint32)
// gRPC message limit, for images and inline scene bundles (scenes of any size stream in
// pieces: scene_chunks.h).
constexpr int kMaxMessageBytes = 512 << 20;
// One task's result at most, raw (its sums and AOV sums before compression): what a worker
// can send in a call with room to spare (admission refuses tiles past it).
constexpr uint64_t kMaxResultBytes = uint64_t(kMaxMessageBytes) * 3 / 4;

// Input from the network that does not make sense: handled and reported, never fatal.
class WireError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// A result's splats declared past the most its task's size allows (decode_splats). An
// honest run of many passes of a large tile can meet it: the coordinator then shortens
// the job's runs (ResultIntake::merge) rather than lease the same run again.
class SplatsOverCap : public WireError {
 public:
  using WireError::WireError;
};

// The longest job name a submit may give (bytes; UTF-8, as every proto string): the
// coordinator refuses longer ones, clients shorten the default name they send to fit.
constexpr size_t kMaxJobNameBytes = 256;

// QUEUED or RUNNING: the one definition of a job that has not ended.
inline bool job_live(v1::JobStatus::State s) { return s == v1::JobStatus::QUEUED || s == v1::JobStatus::RUNNING; }

// A task's passes as sample ranges: [sample_begin, sample_end) for one pass; for a run
// (pass_count > 1), each pass of the run, which must span exactly the task's samples.
// Throws WireError otherwise.
std::vector<std::pair<uint32_t, uint32_t>> task_passes(const v1::Task& task, const RenderSettings& settings);
// A run's base sums (empty without), decoded for a tile of `rect` with `planes` planes of
// sums (RenderSettings::sum_planes()); throws WireError when they do not fit it or come
// with a single pass.
std::vector<PixelSums> task_base(const v1::Task& task, const Rect& rect, uint32_t planes);

// A path that stays inside a folder when joined to it: relative, no "..", no NUL.
bool bundle_relative(const std::string& path);
v1::RenderSettings to_proto(const RenderSettings& s);
// Throws WireError with RenderSettings::validate()'s message for settings out of range.
RenderSettings from_proto(const v1::RenderSettings& p);

v1::Rect to_proto(const Rect& r);
Rect from_proto(const v1::Rect& r);

// A message as JSON with proto field names and every field present (the CLI's --json and
// the status endpoint).
std::string proto_json(const google::protobuf::Message& m);

// Tile sums <-> zstd-compressed little-endian bytes, 36 per pixel, in byte planes: byte 0
// of every pixel's r, then byte 1, ... byte 7, then g, b, lum2 (float64) and n (uint32)
// alike. A sum of a pass's float samples leaves the low bytes of the doubles mostly zero
// and the high bytes alike from pixel to pixel, which planes make easy to compress: half
// the size, and twice as fast, as zstd on whole pixels.
std::string encode_sums(const PixelSums* sums, size_t pixels);
inline std::string encode_sums(const std::vector<PixelSums>& sums) { return encode_sums(sums.data(), sums.size()); }
// Throws WireError unless the data decodes to exactly `pixels` finite pixels.
void decode_sums(const std::string& compressed, PixelSums* out, size_t pixels);
std::vector<PixelSums> decode_sums(const std::string& compressed, size_t pixels);

// AOV sums (core/render/aov.h) <-> zstd-compressed little-endian bytes, kAovBytesPerPixel
// each, field by field in byte planes as encode_sums does.
constexpr size_t kAovBytesPerPixel = 72;
std::string encode_aovs(const AovSums* sums, size_t pixels);
inline std::string encode_aovs(const std::vector<AovSums>& sums) { return encode_aovs(sums.data(), sums.size()); }
// Throws WireError unless the data decodes to exactly `pixels` pixels, each plausible()
// for at most `max_samples` samples.
std::vector<AovSums> decode_aovs(const std::string& compressed, size_t pixels, uint32_t max_samples);

// A task's splat records (core/render/splats.h), one per pass, <-> zstd-compressed
// little-endian bytes: u32 records; per record u64 paths, u64 odd paths, u32 entries; then
// every record's entries in byte planes, field by field (as encode_sums): each index less
// the previous entry's of its record (u32), then r, g, b, squared luminance (i64).
std::string encode_splats(const std::vector<SplatRecord>& records);
// What a task's records may hold: `records` of them (its passes), entries' indices below
// `planes` x `area` (the frame window's pixels), at most `max_paths` light paths a record
// (the tile's pixels x its longest pass's light paths a pixel), each splatting at most
// `max_splats_per_path` times (the path's depth) per plane; and 256 MB decoded in all.
struct SplatLimits {
  size_t records = 0;
  uint64_t area = 0;
  uint32_t planes = 1;
  uint64_t max_paths = 0;
  uint64_t max_splats_per_path = 1;
};
// Throws WireError unless the data holds exactly limits.records records within the limits,
// each entry's index above the previous one's, its sums no more than its record's paths
// could add (kMaxSplatValue per splat), odd-plane entries and paths only with two planes.
std::vector<SplatRecord> decode_splats(const std::string& compressed, const SplatLimits& limits);
// The bytes a result's splats would take decoded, as their zstd frame declares them, at most
// the most any result may carry (decode_splats refuses more); 0 where none is declared.
uint64_t splats_declared_bytes(const std::string& compressed);

}  // namespace tessera
