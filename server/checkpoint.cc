#include "server/checkpoint.h"

#include <zstd.h>
#define XXH_INLINE_ALL  // header only: nothing to link
#include <xxhash.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>

#include "wire.h"

namespace tessera {

namespace {

constexpr char kMagic[4] = {'T', 'S', 'C', 'K'};
// Version 2: the film's sums in chunks of kChunkPixels, each compressed on its own (a
// whole film as one buffer took 8 times as long per pixel: caches, and page faults for
// buffers of the film's size). Version 1 is still read.
constexpr uint32_t kCheckpointVersion = 2;
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

std::string encode_checkpoint(const PlanState& state, const Film& film, double elapsed) {
  Writer w;
  w.out.append(kMagic, 4);
  w.put(kCheckpointVersion);
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

Checkpoint decode_checkpoint(const std::string& bytes, bool with_film) {
  if (bytes.size() < 4 + 8 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    throw std::runtime_error("checkpoint: not a checkpoint file");
  uint64_t sum;
  std::memcpy(&sum, bytes.data() + bytes.size() - 8, 8);
  if (XXH64(bytes.data(), bytes.size() - 8, 0) != sum) throw std::runtime_error("checkpoint: checksum mismatch");
  Reader in(bytes);
  in.get<uint32_t>();  // magic
  const uint32_t version = in.get<uint32_t>();
  if (version != 1 && version != kCheckpointVersion)
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

}  // namespace tessera
