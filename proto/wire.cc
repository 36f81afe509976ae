#include "wire.h"

#include <google/protobuf/util/json_util.h>
#include <zstd.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <limits>

#include "core/render/frame_plan.h"
#include "core/util/text.h"

namespace tessera {

bool bundle_relative(const std::string& path) {
  const std::filesystem::path p(path);
  if (p.empty() || p.is_absolute() || path.find('\0') != std::string::npos) return false;
  for (const auto& part : p)
    if (part == "..") return false;
  return true;
}

v1::RenderSettings to_proto(const RenderSettings& s) {
  v1::RenderSettings p;
  p.set_spp(uint32_t(s.spp));
  p.set_light_samples(uint32_t(s.light_samples));
  p.set_max_depth(uint32_t(s.max_depth));
  p.set_adaptive(s.adaptive);
  p.set_adaptive_batch(uint32_t(s.adaptive_batch));
  p.set_adaptive_tolerance(s.adaptive_tolerance);
  p.set_seed(s.seed);
  if (s.frame) p.set_frame(*s.frame);
  p.set_fps(s.fps);
  if (s.camera.path) p.set_camera_path(s.camera.path->to_json());
  p.set_animation(s.animation);
  if (s.environment)
    for (const float c : {s.environment->r, s.environment->g, s.environment->b}) p.add_environment(c);
  p.set_no_default_environment(!s.default_environment);
  p.set_environment_map(s.environment_map);
  if (s.environment_strength != 1) p.set_environment_strength(s.environment_strength);
  p.set_environment_rotation(s.environment_rotation);
  p.set_exposure(s.exposure);
  p.set_pass_spp(uint32_t(s.pass_spp));
  p.set_width(uint32_t(s.camera.width));
  p.set_height(uint32_t(s.camera.height));
  p.set_lens_radius(s.camera.lens_radius);
  p.set_focal_distance(s.camera.focal_distance);
  p.set_framing(s.camera.framing == Framing::kFile ? v1::RenderSettings::FILE : v1::RenderSettings::CS184);
  *p.mutable_window() = to_proto(s.window);
  p.set_tile_size(uint32_t(s.tile_size));
  p.set_noise_target(s.noise_target);
  p.set_no_nee(!s.nee);
  p.set_no_mis(!s.mis);
  p.set_aovs(s.aovs);
  p.set_denoise(s.denoise);
  p.set_light_tracer(uint32_t(s.light_tracer));
  if (s.splat_exponent) p.set_splat_exponent(uint32_t(*s.splat_exponent));
  return p;
}

RenderSettings from_proto(const v1::RenderSettings& p) {
  // Unsigned wire values past INT_MAX would wrap: clamp so validate() sees them too large.
  auto i = [](uint32_t v) { return int(std::min<uint32_t>(v, uint32_t(INT32_MAX))); };
  RenderSettings s;
  s.spp = i(p.spp());
  s.light_samples = i(p.light_samples());
  s.max_depth = i(p.max_depth());
  s.adaptive = p.adaptive();
  s.adaptive_batch = i(p.adaptive_batch());
  s.adaptive_tolerance = p.adaptive_tolerance();
  s.seed = p.seed();
  if (p.has_frame()) s.frame = p.frame();
  if (p.fps() != 0) s.fps = p.fps();  // a message without it: the default
  s.animation = p.animation();
  if (p.environment_size() != 0 && p.environment_size() != 3)
    throw WireError("render settings: environment needs 3 values, got " + std::to_string(p.environment_size()));
  if (p.environment_size() == 3) s.environment = Rgb(p.environment(0), p.environment(1), p.environment(2));
  s.default_environment = !p.no_default_environment();
  s.environment_map = p.environment_map();
  if (!s.environment_map.empty() && !bundle_relative(s.environment_map))
    throw WireError("render settings: environment_map '" + utf8_prefix(s.environment_map, 256) +
                    "' must name a file inside the scene bundle (a relative path without ..)");
  if (p.has_environment_strength()) s.environment_strength = p.environment_strength();
  s.environment_rotation = p.environment_rotation();
  s.exposure = p.exposure();
  s.pass_spp = i(p.pass_spp());
  s.camera.width = i(p.width());
  s.camera.height = i(p.height());
  s.camera.lens_radius = p.lens_radius();
  s.camera.focal_distance = p.focal_distance();
  s.camera.framing = p.framing() == v1::RenderSettings::FILE ? Framing::kFile : Framing::kCs184;
  s.window = Rect{i(p.window().x()), i(p.window().y()), i(p.window().w()), i(p.window().h())};
  s.tile_size = i(p.tile_size());
  s.noise_target = p.noise_target();
  s.nee = !p.no_nee();
  s.mis = !p.no_mis();
  s.aovs = p.aovs();
  s.denoise = p.denoise();
  if (p.light_tracer() > uint32_t(RenderSettings::LightTracer::kAuto))
    throw WireError("render settings: light_tracer " + std::to_string(p.light_tracer()) + " is not 0, 1 or 2");
  s.light_tracer = RenderSettings::LightTracer(p.light_tracer());
  // (Absent: 0, as every job before it; a worker never computes its own.)
  if (p.splat_exponent() > uint32_t(kMaxSplatExponent))
    throw WireError("render settings: splat_exponent " + std::to_string(p.splat_exponent()) + " is past " +
                    std::to_string(kMaxSplatExponent));
  s.splat_exponent = int(p.splat_exponent());
  try {
    if (!p.camera_path().empty())
      s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(p.camera_path()));
    s.validate();
  } catch (const SettingsError& e) {
    throw WireError(std::string("render settings: ") + e.what());
  }
  return s;
}

std::vector<std::pair<uint32_t, uint32_t>> task_passes(const v1::Task& task, const RenderSettings& settings) {
  if (task.sample_begin() >= task.sample_end()) throw WireError("task: no samples");
  if (task.pass_count() <= 1) return {{task.sample_begin(), task.sample_end()}};
  auto run = pass_run(settings, task.pass(), task.pass_count());
  if (run.empty() || run.front().first != task.sample_begin() || run.back().second != task.sample_end())
    throw WireError("task: passes " + std::to_string(task.pass()) + "+" + std::to_string(task.pass_count()) +
                    " do not span samples " + std::to_string(task.sample_begin()) + " to " +
                    std::to_string(task.sample_end()));
  return run;
}

std::vector<PixelSums> task_base(const v1::Task& task, const Rect& rect, uint32_t planes) {
  if (task.base_sums().empty()) return {};
  if (task.pass_count() <= 1) throw WireError("task: base sums without a run of passes");
  return decode_sums(task.base_sums(), size_t(std::max<int64_t>(0, rect.area())) * planes);
}

v1::Rect to_proto(const Rect& r) {
  v1::Rect p;
  p.set_x(uint32_t(r.x));
  p.set_y(uint32_t(r.y));
  p.set_w(uint32_t(r.w));
  p.set_h(uint32_t(r.h));
  return p;
}

Rect from_proto(const v1::Rect& r) {
  constexpr uint32_t kMax = RenderSettings::kMaxImageSide;
  if (r.x() > kMax || r.y() > kMax || r.w() > kMax || r.h() > kMax) throw WireError("rectangle out of range");
  return Rect{int(r.x()), int(r.y()), int(r.w()), int(r.h())};
}

std::string proto_json(const google::protobuf::Message& m) {
  google::protobuf::util::JsonPrintOptions o;
  o.always_print_primitive_fields = true;
  o.preserve_proto_field_names = true;
  std::string s;
  (void)google::protobuf::util::MessageToJsonString(m, &s, o);
  return s;
}

namespace {
// A pixel's fields in wire order, as little-endian integers of 8 or 4 bytes (x86-64 is
// little-endian).
struct Field {
  size_t offset, bytes;
};
constexpr Field kFields[] = {{offsetof(PixelSums, r), 8},
                             {offsetof(PixelSums, g), 8},
                             {offsetof(PixelSums, b), 8},
                             {offsetof(PixelSums, lum2), 8},
                             {offsetof(PixelSums, n), 4}};
static_assert(8 * 4 + 4 == kBytesPerPixel);

// zstd contexts and scratch space kept per thread: a fresh context for every tile costs
// more than compressing it (its tables are allocated, cleared and given back each time).
struct ZstdScratch {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_DCtx* d = ZSTD_createDCtx();
  std::vector<uint8_t> raw, packed;  // byte planes; compressed
  std::vector<uint64_t> values;
  ZstdScratch() {
    if (!c || !d) throw std::bad_alloc();
  }
  ~ZstdScratch() {
    ZSTD_freeCCtx(c);
    ZSTD_freeDCtx(d);
  }
};
// The thread's scratch for one call. Buffers grown past a few tiles' worth (a checkpoint's
// whole film) are given back afterwards: every gRPC thread would otherwise keep one.
class Scratch {
 public:
  Scratch() : z_(get()) {}
  ~Scratch() {
    if (z_.raw.capacity() > (4u << 20)) z_.raw = {};
    if (z_.packed.capacity() > (4u << 20)) z_.packed = {};
    if (z_.values.capacity() > (1u << 20)) z_.values = {};
  }
  ZstdScratch* operator->() { return &z_; }

 private:
  static ZstdScratch& get() {
    thread_local ZstdScratch s;
    return s;
  }
  ZstdScratch& z_;
};
// z's byte planes (raw), zstd-compressed.
std::string compress_planes(Scratch& z) {
  z->packed.resize(ZSTD_compressBound(z->raw.size()));
  const size_t size = ZSTD_compressCCtx(z->c, z->packed.data(), z->packed.size(), z->raw.data(), z->raw.size(), 1);
  if (ZSTD_isError(size)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(size));
  return std::string(reinterpret_cast<const char*>(z->packed.data()), size);
}
// Decompresses exactly `want` bytes of planes into z->raw; throws WireError("WHAT: ...")
// for anything else (not zstd, another size declared or found).
void decompress_planes(Scratch& z, const std::string& compressed, size_t want, const char* what) {
  const std::string w(what);
  const unsigned long long declared = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) throw WireError(w + ": not zstd data");
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != want)
    throw WireError(w + ": " + std::to_string(declared) + " bytes declared, " + std::to_string(want) + " expected");
  z->raw.resize(want);
  const size_t n = ZSTD_decompressDCtx(z->d, z->raw.data(), z->raw.size(), compressed.data(), compressed.size());
  if (ZSTD_isError(n)) throw WireError(w + ": " + ZSTD_getErrorName(n));
  if (n != want) throw WireError(w + ": " + std::to_string(n) + " bytes, " + std::to_string(want) + " expected");
}
// Gathers B byte planes of n bytes each (plane k: byte k of every value) into n
// little-endian values of B bytes, written sizeof(PixelSums) apart from `out` on.
template <int B>
void gather_planes(const uint8_t* plane, size_t n, char* out) {
  static_assert(B == 8 || B == 4);
  size_t i = 0;
#ifdef __SSE2__
  // Eight values at a time: an 8 x B byte transpose in unpack steps (B = 4: two groups of
  // four values).
  auto row = [&](int k) { return _mm_loadl_epi64(reinterpret_cast<const __m128i*>(plane + size_t(k) * n + i)); };
  constexpr size_t kStride = sizeof(PixelSums);
  for (; i + 8 <= n; i += 8, out += 8 * kStride) {
    if constexpr (B == 8) {
      const __m128i a0 = _mm_unpacklo_epi8(row(0), row(1)), a1 = _mm_unpacklo_epi8(row(2), row(3));
      const __m128i a2 = _mm_unpacklo_epi8(row(4), row(5)), a3 = _mm_unpacklo_epi8(row(6), row(7));
      const __m128i b0 = _mm_unpacklo_epi16(a0, a1), b1 = _mm_unpackhi_epi16(a0, a1);
      const __m128i b2 = _mm_unpacklo_epi16(a2, a3), b3 = _mm_unpackhi_epi16(a2, a3);
      const __m128i c[4] = {_mm_unpacklo_epi32(b0, b2), _mm_unpackhi_epi32(b0, b2), _mm_unpacklo_epi32(b1, b3),
                            _mm_unpackhi_epi32(b1, b3)};
      for (int j = 0; j < 4; ++j) {  // values 2j and 2j + 1
        _mm_storel_epi64(reinterpret_cast<__m128i*>(out + 2 * j * kStride), c[j]);
        _mm_storel_epi64(reinterpret_cast<__m128i*>(out + (2 * j + 1) * kStride), _mm_unpackhi_epi64(c[j], c[j]));
      }
    } else {
      const __m128i a0 = _mm_unpacklo_epi8(row(0), row(1)), a1 = _mm_unpacklo_epi8(row(2), row(3));
      alignas(16) uint32_t values[8];
      _mm_store_si128(reinterpret_cast<__m128i*>(values), _mm_unpacklo_epi16(a0, a1));
      _mm_store_si128(reinterpret_cast<__m128i*>(values + 4), _mm_unpackhi_epi16(a0, a1));
      for (int j = 0; j < 8; ++j) std::memcpy(out + j * kStride, &values[j], 4);
    }
  }
#endif
  for (; i < n; ++i, out += sizeof(PixelSums)) {
    uint64_t v = 0;
    for (int k = 0; k < B; ++k) v |= uint64_t(plane[size_t(k) * n + i]) << (8 * k);
    std::memcpy(out, &v, B);
  }
}
}  // namespace

std::string encode_sums(const PixelSums* sums, size_t n) {
  Scratch z;
  z->raw.resize(n * kBytesPerPixel);
  z->values.resize(n);
  uint8_t* plane = z->raw.data();
  uint64_t* v = z->values.data();
  for (const Field& f : kFields) {  // field by field, then byte by byte: loops that vectorize
    if (n == 0) break;              // (no pointer arithmetic on an empty array)
    const char* in = reinterpret_cast<const char*>(sums) + f.offset;
    if (f.bytes == 8)  // (copies of a constant size: moves, not calls)
      for (size_t i = 0; i < n; ++i, in += sizeof(PixelSums)) std::memcpy(&v[i], in, 8);
    else
      for (size_t i = 0; i < n; ++i, in += sizeof(PixelSums)) {
        uint32_t u;
        std::memcpy(&u, in, 4);
        v[i] = u;
      }
    for (size_t k = 0; k < f.bytes; ++k, plane += n)
      for (size_t i = 0; i < n; ++i) plane[i] = uint8_t(v[i] >> (8 * k));
  }
  return compress_planes(z);
}

std::vector<PixelSums> decode_sums(const std::string& compressed, size_t pixels) {
  std::vector<PixelSums> sums(pixels);
  decode_sums(compressed, sums.data(), pixels);
  return sums;
}

void decode_sums(const std::string& compressed, PixelSums* sums, size_t pixels) {
  Scratch z;
  decompress_planes(z, compressed, pixels * kBytesPerPixel, "sums");
  if (pixels == 0) return;  // (no planes: and no pointer arithmetic on an empty vector)
  const uint8_t* plane = z->raw.data();
  for (const Field& f : kFields) {  // each pixel's field from its byte planes
    char* out = reinterpret_cast<char*>(sums) + f.offset;
    if (f.bytes == 8)
      gather_planes<8>(plane, pixels, out);
    else
      gather_planes<4>(plane, pixels, out);
    plane += f.bytes * pixels;
  }
  for (const PixelSums* p = sums; p != sums + pixels; ++p)
    if (!std::isfinite(p->r) || !std::isfinite(p->g) || !std::isfinite(p->b) || !std::isfinite(p->lum2))
      throw WireError("sums: non-finite value");
}

namespace {
constexpr Field kAovFields[] = {
    {offsetof(AovSums, n), 4},          {offsetof(AovSums, hits), 4},        {offsetof(AovSums, albedo), 8},
    {offsetof(AovSums, albedo) + 8, 8}, {offsetof(AovSums, albedo) + 16, 8}, {offsetof(AovSums, normal), 8},
    {offsetof(AovSums, normal) + 8, 8}, {offsetof(AovSums, normal) + 16, 8}, {offsetof(AovSums, distance), 8},
    {offsetof(AovSums, id), 4},         {offsetof(AovSums, id_sample), 4}};
constexpr size_t aov_field_bytes() {
  size_t n = 0;
  for (const Field& f : kAovFields) n += f.bytes;
  return n;
}
static_assert(aov_field_bytes() == kAovBytesPerPixel);
}  // namespace

std::string encode_aovs(const AovSums* sums, size_t n) {
  Scratch z;
  z->raw.resize(n * kAovBytesPerPixel);
  uint8_t* plane = z->raw.data();
  for (const Field& f : kAovFields) {
    for (size_t i = 0; i < n; ++i) {
      uint64_t v = 0;
      std::memcpy(&v, reinterpret_cast<const char*>(sums + i) + f.offset, f.bytes);
      for (size_t k = 0; k < f.bytes; ++k) plane[k * n + i] = uint8_t(v >> (8 * k));
    }
    plane += f.bytes * n;
  }
  return compress_planes(z);
}

std::vector<AovSums> decode_aovs(const std::string& compressed, size_t pixels, uint32_t max_samples) {
  Scratch z;
  decompress_planes(z, compressed, pixels * kAovBytesPerPixel, "AOV sums");
  std::vector<AovSums> out(pixels);
  const uint8_t* plane = z->raw.data();
  for (const Field& f : kAovFields) {
    for (size_t i = 0; i < pixels; ++i) {
      uint64_t v = 0;
      for (size_t k = 0; k < f.bytes; ++k) v |= uint64_t(plane[k * pixels + i]) << (8 * k);
      std::memcpy(reinterpret_cast<char*>(&out[i]) + f.offset, &v, f.bytes);
    }
    plane += f.bytes * pixels;
  }
  for (const AovSums& a : out)
    if (!a.plausible(max_samples)) throw WireError("AOV sums: a pixel's sums no render could give");
  return out;
}

namespace {

constexpr size_t kSplatRecordBytes = 8 + 8 + 4, kSplatEntryBytes = 4 + 4 * 8;
// A result's splats at most, decoded (whatever its task): far above an honest task's (a
// 64 x 64 tile's pass of 64 samples: 65,536 light paths, a few splats each, under 10 MB).
constexpr uint64_t kMaxSplatBytes = uint64_t(256) << 20;

template <typename T>
void put_le(std::vector<uint8_t>& out, T v) {
  const size_t at = out.size();
  out.resize(at + sizeof v);
  std::memcpy(out.data() + at, &v, sizeof v);
}

// Reads the decoded records' fields in order; WireError past the end.
class SplatReader {
 public:
  explicit SplatReader(const std::vector<uint8_t>& raw) : raw_(raw) {}
  template <typename T>
  T get() {
    T v;
    if (raw_.size() - at_ < sizeof v) throw WireError("splats: cut short");
    std::memcpy(&v, raw_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }

 private:
  const std::vector<uint8_t>& raw_;
  size_t at_ = 0;
};

}  // namespace

std::string encode_splats(const std::vector<SplatRecord>& records) {
  Scratch z;
  z->raw.clear();
  put_le(z->raw, uint32_t(records.size()));
  size_t total = 0;
  for (const SplatRecord& r : records) {
    put_le(z->raw, r.paths);
    put_le(z->raw, r.odd_paths);
    put_le(z->raw, uint32_t(r.entries.size()));
    total += r.entries.size();
  }
  // The entries of every record in byte planes, field by field (as encode_sums): index
  // steps are mostly one byte and sums a few, which planes let zstd see.
  const size_t at = z->raw.size();
  z->raw.resize(at + total * kSplatEntryBytes);
  uint8_t* plane = z->raw.data() + at;
  auto field = [&](int bytes, auto value) {
    size_t i = 0;
    for (const SplatRecord& r : records)
      for (size_t k = 0; k < r.entries.size(); ++k, ++i) {
        const uint64_t v = value(r, k);
        for (int b = 0; b < bytes; ++b) plane[size_t(b) * total + i] = uint8_t(v >> (8 * b));
      }
    plane += size_t(bytes) * total;
  };
  field(4,
        [](const SplatRecord& r, size_t k) { return uint64_t(r.entries[k].index - (k ? r.entries[k - 1].index : 0)); });
  for (int c = 0; c < 4; ++c) field(8, [c](const SplatRecord& r, size_t k) { return uint64_t(r.entries[k].v[c]); });
  return compress_planes(z);
}

uint64_t splats_declared_bytes(const std::string& compressed) {
  const unsigned long long declared = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN) return 0;
  return std::min<uint64_t>(declared, kMaxSplatBytes);
}

std::vector<SplatRecord> decode_splats(const std::string& compressed, const SplatLimits& lim) {
  // The largest honest size, checked before anything is allocated: a few bytes of zstd
  // can declare gigabytes.
  const uint64_t per_record =
      std::min<uint64_t>(lim.area * lim.planes, lim.max_paths * lim.max_splats_per_path * lim.planes);
  const uint64_t cap =
      std::min<uint64_t>(kMaxSplatBytes, 4 + lim.records * (kSplatRecordBytes + per_record * kSplatEntryBytes));
  const unsigned long long declared = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) throw WireError("splats: not zstd data");
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN) throw WireError("splats: no size declared");
  if (declared > cap)
    throw SplatsOverCap("splats: " + std::to_string(declared) + " bytes declared, at most " + std::to_string(cap) +
                        " fit the task");
  Scratch z;
  z->raw.resize(declared);
  const size_t n = ZSTD_decompressDCtx(z->d, z->raw.data(), z->raw.size(), compressed.data(), compressed.size());
  if (ZSTD_isError(n)) throw WireError(std::string("splats: ") + ZSTD_getErrorName(n));
  if (n != declared) throw WireError("splats: fewer bytes than declared");
  SplatReader in(z->raw);
  if (in.get<uint32_t>() != lim.records)
    throw WireError("splats: not one record per pass of the task (" + std::to_string(lim.records) + ")");
  // Every header first: the entries they claim must be what the bytes hold before any is
  // allocated.
  std::vector<SplatRecord> out(lim.records);
  std::vector<uint32_t> counts(lim.records);
  uint64_t total = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    SplatRecord& r = out[i];
    r.paths = in.get<uint64_t>();
    r.odd_paths = in.get<uint64_t>();
    counts[i] = in.get<uint32_t>();
    if (r.paths > lim.max_paths || r.odd_paths > r.paths || (lim.planes < 2 && r.odd_paths))
      throw WireError("splats: more light paths than the task's samples");
    if (counts[i] > per_record) throw WireError("splats: more pixels than the task's light paths reach");
    total += counts[i];
  }
  const size_t at = 4 + lim.records * kSplatRecordBytes;
  if (z->raw.size() != at + total * kSplatEntryBytes) throw WireError("splats: not the entries' size");
  for (size_t i = 0; i < out.size(); ++i) out[i].entries.resize(counts[i]);
  const uint8_t* plane = z->raw.data() + at;
  auto field = [&](int bytes, auto store) {
    size_t i = 0;
    for (SplatRecord& r : out)
      for (size_t k = 0; k < r.entries.size(); ++k, ++i) {
        uint64_t v = 0;
        for (int b = 0; b < bytes; ++b) v |= uint64_t(plane[size_t(b) * total + i]) << (8 * b);
        store(r, k, v);
      }
    plane += size_t(bytes) * total;
  };
  field(4, [](SplatRecord& r, size_t k, uint64_t step) {
    const uint64_t index = (k ? uint64_t(r.entries[k - 1].index) : 0) + step;
    if ((k > 0 && step == 0) || index > 0xffffffffu) throw WireError("splats: indices out of order");
    r.entries[k].index = uint32_t(index);
  });
  for (int c = 0; c < 4; ++c) field(8, [c](SplatRecord& r, size_t k, uint64_t v) { r.entries[k].v[c] = int64_t(v); });
  // Each entry against its record: within the frame's planes, and no more than its light
  // paths could add (a splat's channels are at most kMaxSplatValue: 2^44 in 2^-24 units,
  // squared luminance at most SplatSums::kMaxLum2Units, 2^62; at most max_splats_per_path
  // splats a path).
  const uint64_t planes_area = lim.area * lim.planes;
  for (const SplatRecord& r : out)
    for (const SplatEntry& e : r.entries) {
      if (e.index >= planes_area) throw WireError("splats: indices out of order");
      const uint64_t paths_here = (e.index >= lim.area ? r.odd_paths : r.paths) * lim.max_splats_per_path;
      for (int c = 0; c < 4; ++c)
        if (e.v[c] < 0 || (e.v[c] > 0 && paths_here == 0) || (uint64_t(e.v[c]) >> (c < 3 ? 44 : 62)) > paths_here)
          throw WireError("splats: sums no light path could give");
      // Non-negative splats: their squared luminances sum to at most their luminance sum's
      // square, give or take each one's rounding (at most paths_here splats; 2^-24 units
      // for the channels, 2^-32 for the squares; the luminance in float, well within the
      // margin). Saturated channels bound nothing.
      constexpr int64_t kSaturated = std::numeric_limits<int64_t>::max();
      if (e.v[0] < kSaturated && e.v[1] < kSaturated && e.v[2] < kSaturated) {
        const double k = double(paths_here);
        const double lum = double(Rgb(float(e.v[0]), float(e.v[1]), float(e.v[2])).luminance()) + 0.5 * k;
        if (double(e.v[3]) > lum * lum * 0x1p-16 * (1 + 1e-4) + 0.5 * k + 1)
          throw WireError("splats: a squared luminance no light path could give");
      }
    }
  return out;
}

}  // namespace tessera
