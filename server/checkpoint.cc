#include "server/checkpoint.h"

#include <zstd.h>
#define XXH_INLINE_ALL  // header only: nothing to link
// GCC 12 at -O3 reports array bounds inside xxhash's inlined streaming code when it is fed
// a few bytes at a time (a false positive of its own header: the reads are within the
// input). Quieted for this header only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
#include <xxhash.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "wire.h"

namespace tessera {

namespace {

constexpr char kMagic[4] = {'T', 'S', 'C', 'K'};
// Version 2: the film's sums in chunks of kChunkPixels, each compressed on its own (a
// whole film as one buffer took 8 times as long per pixel: caches, and page faults for
// buffers of the film's size). Version 1 is still read.
// Version 3: band by band (checkpoint.h).
// Version 4: version 3 and the splats (checkpoint.h).
// Version 5: version 4 with the splats' squared luminance in 2^-32 units, not 2^-12
// (SplatSums::kLum2Unit); version 4's are scaled on reading.
constexpr uint32_t kVersion2 = 2, kVersion3 = 3, kVersion4 = 4, kVersion5 = 5, kVersion6 = 6;
constexpr int kVersion4Lum2Shift = 20;  // 2^-12 units to 2^-32
constexpr uint32_t kChunkPixels = 1 << 16;

// Little-endian fields, appended and read back in order.
class Writer {
 public:
  template <typename T>
  void put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  void bytes(const std::string& b) {
    put(uint64_t(b.size()));
    out += b;
  }
  std::string out;
};

class Reader {
 public:
  explicit Reader(const std::string& in) : in_(in) {}
  template <typename T>
  T get() {
    T v;
    need(sizeof v);
    std::memcpy(&v, in_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }
  std::string bytes() {
    const uint64_t n = get<uint64_t>();
    need(n);
    std::string b = in_.substr(at_, n);
    at_ += n;
    return b;
  }
  size_t at() const { return at_; }

 private:
  void need(uint64_t n) const {
    if (n > in_.size() - at_) throw std::runtime_error("checkpoint: truncated");
  }
  const std::string& in_;
  size_t at_ = 0;
};

}  // namespace

std::string encode_checkpoint_v2(const PlanState& state, const Film& film, double elapsed) {
  Writer w;
  w.out.append(kMagic, 4);
  w.put(kVersion2);
  w.put(uint32_t(state.progress.size()));
  for (const TileProgress& t : state.progress) {
    w.put(t.passes_done);
    w.put(uint8_t(t.finished));
    w.put(t.relative_error);
  }
  w.put(state.samples_merged);
  w.put(state.merges);
  w.put(state.work_done);
  w.put(state.work_total);
  w.put(elapsed);
  const Rect& r = film.window();
  for (int v : {r.x, r.y, r.w, r.h}) w.put(int32_t(v));
  std::string active(ZSTD_compressBound(state.active.size()), '\0');
  const size_t n = ZSTD_compress(active.data(), active.size(), state.active.data(), state.active.size(), 1);
  if (ZSTD_isError(n)) throw std::runtime_error("checkpoint: cannot compress the active mask");
  active.resize(n);
  w.put(uint64_t(state.active.size()));
  w.bytes(active);
  const std::vector<PixelSums>& pixels = film.pixels();
  std::vector<std::string> chunks;
  size_t size = w.out.size() + 4 + 8;
  for (size_t at = 0; at < pixels.size(); at += kChunkPixels) {
    chunks.push_back(encode_sums(pixels.data() + at, std::min<size_t>(kChunkPixels, pixels.size() - at)));
    size += 8 + chunks.back().size();
  }
  w.out.reserve(size);  // (appending a film's worth piece by piece would copy it many times)
  w.put(kChunkPixels);
  for (const std::string& c : chunks) w.bytes(c);
  w.put(uint64_t(XXH64(w.out.data(), w.out.size(), 0)));
  return std::move(w.out);
}

Checkpoint decode_checkpoint(const std::string& bytes, bool with_film, const Rect* expected) {
  if (bytes.size() < 4 + 8 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    throw std::runtime_error("checkpoint: not a checkpoint file");
  uint64_t sum;
  std::memcpy(&sum, bytes.data() + bytes.size() - 8, 8);
  if (XXH64(bytes.data(), bytes.size() - 8, 0) != sum) throw std::runtime_error("checkpoint: checksum mismatch");
  Reader in(bytes);
  in.get<uint32_t>();  // magic
  const uint32_t version = in.get<uint32_t>();
  if (version != 1 && version != kVersion2)
    throw std::runtime_error("checkpoint: version " + std::to_string(version) + " not supported");
  Checkpoint c;
  const uint32_t tiles = in.get<uint32_t>();
  if (uint64_t(tiles) * 9 > bytes.size()) throw std::runtime_error("checkpoint: truncated");
  c.state.progress.resize(tiles);
  for (TileProgress& t : c.state.progress) {
    t.passes_done = in.get<uint32_t>();
    t.finished = in.get<uint8_t>() != 0;
    t.relative_error = in.get<float>();
  }
  c.state.samples_merged = in.get<uint64_t>();
  c.state.merges = in.get<uint64_t>();
  c.state.work_done = in.get<double>();
  c.state.work_total = in.get<double>();
  c.elapsed = in.get<double>();
  Rect r;
  r.x = in.get<int32_t>();
  r.y = in.get<int32_t>();
  r.w = in.get<int32_t>();
  r.h = in.get<int32_t>();
  if (r.w < 0 || r.h < 0 || r.area() > (int64_t(1) << 32)) throw std::runtime_error("checkpoint: bad film window");
  if (expected && !(r == *expected)) throw std::runtime_error("checkpoint: it does not fit the job's frame");
  const uint64_t active_size = in.get<uint64_t>();
  if (active_size != 0 && active_size != uint64_t(r.area())) throw std::runtime_error("checkpoint: bad active mask");
  const std::string active = in.bytes();
  c.state.active.resize(active_size);
  if (active_size) {
    const size_t n = ZSTD_decompress(c.state.active.data(), active_size, active.data(), active.size());
    if (ZSTD_isError(n) || n != active_size) throw std::runtime_error("checkpoint: bad active mask");
  }
  const size_t pixels = size_t(r.area());
  const uint32_t chunk = version == 1 ? uint32_t(std::max<size_t>(1, pixels)) : in.get<uint32_t>();
  if (chunk == 0) throw std::runtime_error("checkpoint: bad film chunk size");
  std::vector<std::string> chunks;
  for (size_t at = 0; at < pixels || (version == 1 && chunks.empty()); at += chunk) chunks.push_back(in.bytes());
  if (in.at() != bytes.size() - 8) throw std::runtime_error("checkpoint: trailing bytes");
  if (!with_film) return c;
  c.film = Film(r);
  try {
    for (size_t i = 0, at = 0; i < chunks.size() && at < pixels; ++i, at += chunk)
      decode_sums(chunks[i], &c.film.at(0, 0) + at, std::min<size_t>(chunk, pixels - at));
  } catch (const WireError& e) {
    throw std::runtime_error(std::string("checkpoint: film: ") + e.what());
  }
  return c;
}

// ---- version 3 ----

struct CheckpointEncoder::Hash {
  XXH64_state_t* st = XXH64_createState();
  Hash() { XXH64_reset(st, 0); }
  ~Hash() { XXH64_freeState(st); }
};

CheckpointEncoder::CheckpointEncoder(const FramePlan& plan, double elapsed, std::function<void(const std::string&)> out,
                                     bool film)
    : out_(std::move(out)),
      hash_(std::make_unique<Hash>()),
      adaptive_(plan.settings().adaptive),
      aovs_(plan.settings().aovs != 0),
      halves_(plan.settings().halves()),
      film_(film) {
  Writer w;
  w.out.append(kMagic, 4);
  w.put(kVersion6);
  const Rect r = plan.settings().effective_window();
  for (int v : {r.x, r.y, r.w, r.h}) w.put(int32_t(v));
  w.put(uint32_t(plan.tiles().size()));
  w.put(plan.bands());
  w.put(uint8_t(adaptive_));
  w.put(uint8_t(film_));
  w.put(elapsed);
  emit(std::move(w.out));
}

CheckpointEncoder::~CheckpointEncoder() = default;

void CheckpointEncoder::emit(std::string bytes) {
  XXH64_update(hash_->st, bytes.data(), bytes.size());
  out_(bytes);
}

void CheckpointEncoder::band(const BandCopy& b) {
  Writer w;
  w.put(b.band);
  w.put(uint32_t(b.progress.size()));
  for (const TileProgress& t : b.progress) {
    w.put(t.passes_done);
    w.put(uint8_t(t.finished));
    w.put(t.relative_error);
  }
  w.put(b.samples);
  if (!film_) return emit(std::move(w.out));  // the progress alone
  if (adaptive_) {
    std::string mask(ZSTD_compressBound(b.active.size()), '\0');
    const size_t n = ZSTD_compress(mask.data(), mask.size(), b.active.data(), b.active.size(), 1);
    if (ZSTD_isError(n)) throw std::runtime_error("checkpoint: cannot compress the active mask");
    mask.resize(n);
    w.put(uint64_t(b.active.size()));
    w.bytes(mask);
  }
  w.bytes(encode_sums(b.pixels.data(), b.pixels.size()));
  if (aovs_) w.bytes(encode_aovs(b.aovs));                        // a job with AOVs: their sums follow the film's
  if (halves_) w.bytes(encode_sums(b.odd.data(), b.odd.size()));  // then the film's second plane
  emit(std::move(w.out));
}

namespace {

std::string encode_splat_rows(const std::vector<SplatSums>& rows) {
  static_assert(sizeof(SplatSums) == 32, "SplatSums: four int64, no padding");
  std::string out(ZSTD_compressBound(rows.size() * sizeof(SplatSums)), '\0');
  const size_t n = ZSTD_compress(out.data(), out.size(), rows.data(), rows.size() * sizeof(SplatSums), 1);
  if (ZSTD_isError(n)) throw std::runtime_error("checkpoint: cannot compress the splats");
  out.resize(n);
  return out;
}

}  // namespace

void CheckpointEncoder::splats(const FrameSplats::Frozen& f) {
  if (!film_) throw std::logic_error("checkpoint: splats in a checkpoint without the film");
  Writer w;
  w.put(uint8_t(1));
  w.put(f.paths);
  w.put(f.odd_paths);
  for (uint32_t t : f.frontier) w.put(t);
  splats_ = true;
  emit(std::move(w.out));
}

void CheckpointEncoder::splat_band(const BandCopy& b) {
  Writer w;
  w.bytes(encode_splat_rows(b.splats));
  if (halves_) w.bytes(encode_splat_rows(b.odd_splats));
  emit(std::move(w.out));
}

void CheckpointEncoder::finish() {
  if (!splats_) emit(std::string(1, '\0'));  // no splats
  Writer w;
  w.put(uint64_t(XXH64_digest(hash_->st)));
  out_(w.out);
}

std::string encode_checkpoint(const FramePlan& plan, double elapsed, FrameSplats* splats) {
  std::string out;
  CheckpointEncoder enc(plan, elapsed, [&](const std::string& bytes) { out += bytes; });
  BandCopy band;
  for (uint32_t b = 0; b < plan.bands(); ++b) {
    plan.copy_band(b, &band);
    enc.band(band);
  }
  if (splats && splats->any()) {
    const FrameSplats::Frozen frozen = splats->freeze();
    struct Thaw {
      FrameSplats* s;
      ~Thaw() { s->thaw(); }
    } thaw{splats};
    enc.splats(frozen);
    for (uint32_t b = 0; b < plan.bands(); ++b) {
      plan.band_shape(b, &band);
      splats->copy_band(&band);
      enc.splat_band(band);
    }
  }
  enc.finish();
  return out;
}

namespace {

// Fields read from a stream, hashed as they go.
class StreamReader {
 public:
  StreamReader(const std::function<size_t(char*, size_t)>& read, XXH64_state_t* hash) : read_(read), hash_(hash) {}
  void exactly(char* out, size_t n, bool hashed = true) {
    for (size_t at = 0; at < n;) {
      const size_t k = read_(out + at, n - at);
      if (k == 0) throw std::runtime_error("checkpoint: truncated");
      at += k;
    }
    if (hashed) XXH64_update(hash_, out, n);
  }
  template <typename T>
  T get() {
    T v;
    exactly(reinterpret_cast<char*>(&v), sizeof v);
    return v;
  }
  bool at_end() {
    char c;
    return read_(&c, 1) == 0;
  }
  std::string bytes(uint64_t limit) {
    const uint64_t n = get<uint64_t>();
    if (n > limit) throw std::runtime_error("checkpoint: a field of " + std::to_string(n) + " bytes");
    std::string b(n, '\0');
    exactly(b.data(), n);
    return b;
  }

 private:
  const std::function<size_t(char*, size_t)>& read_;
  XXH64_state_t* hash_;
};

// The splat section (versions 4 and 5), after the bands: into `splats` when given (with the film).
void read_splats(StreamReader& in, const FramePlan& plan, FrameSplats* splats, uint32_t version) {
  const uint8_t has = in.get<uint8_t>();
  if (has > 1) throw std::runtime_error("checkpoint: bad splat section");
  if (!has) return;
  FrameSplats::Frozen f;
  f.paths = in.get<uint64_t>();
  f.odd_paths = in.get<uint64_t>();
  f.frontier.resize(plan.tiles().size());
  for (uint32_t& t : f.frontier) {
    t = in.get<uint32_t>();
    if (t > plan.passes().size()) throw std::runtime_error("checkpoint: a splat frontier past the frame's passes");
  }
  if (splats) try {
      splats->restore(f);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(std::string("checkpoint: splats: ") + e.what());
    }
  BandCopy band;
  std::vector<SplatSums> rows;
  for (uint32_t b = 0; b < plan.bands(); ++b) {
    plan.band_shape(b, &band);
    const size_t bytes = size_t(band.rows) * size_t(band.width) * sizeof(SplatSums);
    for (bool odd : {false, true}) {
      if (odd && !plan.settings().halves()) continue;
      const std::string z = in.bytes(ZSTD_compressBound(bytes) + 64);
      if (!splats) continue;
      rows.resize(bytes / sizeof(SplatSums));
      const size_t n = ZSTD_decompress(rows.data(), bytes, z.data(), z.size());
      if (ZSTD_isError(n) || n != bytes) throw std::runtime_error("checkpoint: bad splat rows");
      for (SplatSums& s : rows) {
        if (s.rgb[0] < 0 || s.rgb[1] < 0 || s.rgb[2] < 0 || s.lum2 < 0)
          throw std::runtime_error("checkpoint: negative splat sums");
        if (version == kVersion4)  // saturating, as the sums are
          s.lum2 = s.lum2 > (std::numeric_limits<int64_t>::max() >> kVersion4Lum2Shift)
                       ? std::numeric_limits<int64_t>::max()
                       : s.lum2 << kVersion4Lum2Shift;
      }
      splats->restore_rows(band.y0, band.rows, odd, rows.data());
    }
  }
}

double read_v3(StreamReader& in, XXH64_state_t* hash, FramePlan& plan, bool with_film, uint32_t version,
               FrameSplats* splats) {
  const bool has_film = version < kVersion6 || in.get<uint8_t>() != 0;
  if (with_film && !has_film)
    throw std::runtime_error("checkpoint: it holds no film (a finished frame's, whose image was written)");
  const double elapsed = in.get<double>();
  BandCopy band;
  std::vector<bool> seen(plan.bands(), false);
  for (uint32_t k = 0; k < plan.bands(); ++k) {
    band.band = in.get<uint32_t>();
    if (band.band >= plan.bands() || seen[band.band]) throw std::runtime_error("checkpoint: bands out of order");
    seen[band.band] = true;
    const uint32_t tiles = in.get<uint32_t>();
    if (tiles != plan.tiles_per_band()) throw std::runtime_error("checkpoint: a band of another size");
    band.progress.resize(tiles);
    for (TileProgress& t : band.progress) {
      t.passes_done = in.get<uint32_t>();
      t.finished = in.get<uint8_t>() != 0;
      t.relative_error = in.get<float>();
    }
    band.samples = in.get<uint64_t>();
    plan.band_shape(band.band, &band);
    const size_t pixels = size_t(band.rows) * size_t(band.width);
    band.active.clear();
    band.pixels.clear();
    band.aovs.clear();
    band.odd.clear();
    if (!has_film) {
      try {
        plan.restore_band(band);
      } catch (const std::invalid_argument& e) {
        throw std::runtime_error(std::string("checkpoint: ") + e.what());
      }
      continue;
    }
    if (plan.settings().adaptive) {
      const uint64_t size = in.get<uint64_t>();
      const std::string mask = in.bytes(ZSTD_compressBound(pixels) + 64);
      if (size != pixels) throw std::runtime_error("checkpoint: bad active mask");
      if (with_film) {
        band.active.resize(pixels);
        const size_t n = ZSTD_decompress(band.active.data(), pixels, mask.data(), mask.size());
        if (ZSTD_isError(n) || n != pixels) throw std::runtime_error("checkpoint: bad active mask");
      }
    }
    const std::string sums = in.bytes(uint64_t(pixels) * kBytesPerPixel * 2 + 4096);
    band.pixels.clear();
    if (with_film) try {
        band.pixels.resize(pixels);
        decode_sums(sums, band.pixels.data(), pixels);
      } catch (const WireError& e) {
        throw std::runtime_error(std::string("checkpoint: film: ") + e.what());
      }
    band.aovs.clear();
    if (plan.settings().aovs) {
      const std::string aovs = in.bytes(uint64_t(pixels) * kAovBytesPerPixel * 2 + 4096);
      if (with_film) try {
          band.aovs = decode_aovs(aovs, pixels, RenderSettings::kMaxSpp);
        } catch (const WireError& e) {
          throw std::runtime_error(std::string("checkpoint: AOVs: ") + e.what());
        }
    }
    band.odd.clear();
    if (plan.settings().halves()) {
      const std::string odd = in.bytes(uint64_t(pixels) * kBytesPerPixel * 2 + 4096);
      if (with_film) try {
          band.odd.resize(pixels);
          decode_sums(odd, band.odd.data(), pixels);
        } catch (const WireError& e) {
          throw std::runtime_error(std::string("checkpoint: half-buffers: ") + e.what());
        }
    }
    try {
      plan.restore_band(band);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(std::string("checkpoint: ") + e.what());
    }
  }
  if (version >= kVersion4) read_splats(in, plan, with_film ? splats : nullptr, version);
  const uint64_t digest = XXH64_digest(hash);
  uint64_t sum;
  in.exactly(reinterpret_cast<char*>(&sum), sizeof sum, false);
  if (sum != digest) throw std::runtime_error("checkpoint: checksum mismatch");
  if (!in.at_end()) throw std::runtime_error("checkpoint: trailing bytes");
  plan.restore_finish();
  // The splats were frozen after the bands were copied: no tile's are behind its film's.
  if (with_film && splats && splats->any())
    for (uint32_t t = 0; t < plan.tiles().size(); ++t)
      if (splats->frontier(t) < plan.progress(t).passes_done)
        throw std::runtime_error("checkpoint: a tile's splats behind its film");
  return elapsed;
}

}  // namespace

double read_checkpoint(const std::function<size_t(char*, size_t)>& read, FramePlan& plan, bool with_film,
                       FrameSplats* splats) {
  XXH64_state_t* hash = XXH64_createState();
  struct Free {
    XXH64_state_t* h;
    ~Free() { XXH64_freeState(h); }
  } free_hash{hash};
  XXH64_reset(hash, 0);
  StreamReader in(read, hash);
  char magic[4];
  in.exactly(magic, 4);
  if (std::memcmp(magic, kMagic, 4) != 0) throw std::runtime_error("checkpoint: not a checkpoint file");
  const uint32_t version = in.get<uint32_t>();
  if (version == kVersion3 || version == kVersion4 || version == kVersion5 || version == kVersion6) {
    Rect r;
    r.x = in.get<int32_t>();
    r.y = in.get<int32_t>();
    r.w = in.get<int32_t>();
    r.h = in.get<int32_t>();
    const uint32_t tiles = in.get<uint32_t>(), bands = in.get<uint32_t>();
    const bool adaptive = in.get<uint8_t>() != 0;
    if (!(r == plan.settings().effective_window()) || tiles != plan.tiles().size() || bands != plan.bands() ||
        adaptive != plan.settings().adaptive)
      throw std::runtime_error("checkpoint: it does not fit the job's frame");
    return read_v3(in, hash, plan, with_film, version, splats);
  }
  if (version != 1 && version != kVersion2)
    throw std::runtime_error("checkpoint: version " + std::to_string(version) + " not supported");
  // The old formats, whole: as they were written.
  std::string bytes(kMagic, 4);
  bytes.append(reinterpret_cast<const char*>(&version), 4);
  // Read whole, as they were written: at most what the job's film could make (its sums, raw,
  // and room for the rest), not whatever the file holds.
  const Rect window = plan.settings().effective_window();
  const uint64_t most = uint64_t(window.area()) * (sizeof(PixelSums) + 8) + (uint64_t(1) << 20);
  char buf[1 << 16];
  for (size_t k; (k = read(buf, sizeof buf)) > 0;) {
    bytes.append(buf, k);
    if (bytes.size() > most)
      throw std::runtime_error("checkpoint: larger than the job's film could make (" + std::to_string(most) +
                               " bytes)");
  }
  Checkpoint c = decode_checkpoint(bytes, with_film, &window);
  try {
    plan.restore(c.state, std::move(c.film));
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string("checkpoint: ") + e.what());
  }
  return c.elapsed;
}

double read_checkpoint(const std::string& bytes, FramePlan& plan, bool with_film, FrameSplats* splats) {
  size_t at = 0;
  return read_checkpoint(
      [&](char* out, size_t n) {
        const size_t k = std::min(n, bytes.size() - at);
        std::memcpy(out, bytes.data() + at, k);
        at += k;
        return k;
      },
      plan, with_film, splats);
}

}  // namespace tessera
