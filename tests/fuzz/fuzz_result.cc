// libFuzzer target: what the coordinator decodes from bytes it did not write itself or
// that a crash may have cut short: a worker's tile sums (decode_sums, then the plan's
// plausibility check), its AOV sums (decode_aovs, then added up: no overflow may follow
// from what passes the check) and a film checkpoint (read_checkpoint into a small plan,
// with and without AOVs: every version; decode_checkpoint for versions 1 and 2). The first input byte picks which;
// refusals are WireError / std::runtime_error; a decoded tile must hold only finite numbers. Seeds:
// TESSERA_FUZZ_SEEDS=DIR writes some and exits.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "core/render/frame_plan.h"
#include "server/checkpoint.h"
#include "wire.h"

namespace {
std::vector<tessera::PixelSums> tile(size_t n) {
  std::vector<tessera::PixelSums> s(n);
  for (size_t i = 0; i < n; ++i) s[i] = {0.25 * double(i), 0.5, 1.0 / 3, 0.125 * double(i), uint32_t(i % 5)};
  return s;
}
// The plan fuzzed checkpoints are read into: 4 x 3 tiles of 4 pixels, 3 passes.
tessera::RenderSettings checkpoint_settings() {
  tessera::RenderSettings s;
  s.camera.width = 16;
  s.camera.height = 11;
  s.tile_size = 4;
  s.spp = 6;
  s.pass_spp = 2;
  return s;
}
}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const char* seeds = std::getenv("TESSERA_FUZZ_SEEDS");
  if (!seeds) return 0;
  namespace fs = std::filesystem;
  fs::create_directories(seeds);
  for (const size_t n : {1, 16, 64}) {
    const std::string sums = tessera::encode_sums(tile(n));
    std::ofstream(fs::path(seeds) / ("sums" + std::to_string(n)), std::ios::binary)
        << char(0) << char(n & 0xff) << char(n >> 8) << sums;
  }
  tessera::PlanState st;
  st.progress = {{1, false, 0.5f}, {2, true, 0.25f}};
  st.active.assign(16, 1);
  tessera::Film film(tessera::Rect{0, 0, 4, 4});
  film.add_tile(film.window(), tile(16));
  std::ofstream(fs::path(seeds) / "checkpoint", std::ios::binary)
      << char(1) << tessera::encode_checkpoint_v2(st, film, 2.5);
  tessera::FramePlan plan(checkpoint_settings());
  for (int k = 0; k < 5; ++k) {
    const tessera::TileTask t = *plan.take();
    plan.merge(t.tile, t.pass, tile(size_t(t.rect.area())));
  }
  std::ofstream(fs::path(seeds) / "checkpoint3", std::ios::binary) << char(1) << tessera::encode_checkpoint(plan, 2.5);
  tessera::RenderSettings with_aovs = checkpoint_settings();
  with_aovs.aovs = tessera::kAovAll;
  tessera::FramePlan aov_plan(with_aovs);
  for (int k = 0; k < 5; ++k) {
    const tessera::TileTask t = *aov_plan.take();
    aov_plan.merge(t.tile, t.pass, tile(size_t(t.rect.area())));
    aov_plan.add_aovs(t.tile, std::vector<tessera::AovSums>(size_t(t.rect.area())));
  }
  std::ofstream(fs::path(seeds) / "checkpoint3aov", std::ios::binary)
      << char(1) << tessera::encode_checkpoint(aov_plan, 2.5);
  std::vector<tessera::AovSums> aovs(16);
  tessera::FirstHit hit;
  hit.hit = true;
  hit.distance = 2;
  hit.albedo = tessera::Rgb(0.5f);
  for (size_t i = 0; i < aovs.size(); ++i) aovs[i].add_sample(hit, uint32_t(i));
  std::ofstream(fs::path(seeds) / "aovs16", std::ios::binary)
      << char(2) << char(16) << char(0) << tessera::encode_aovs(aovs);
  // Splat records (a task's, wire.h) and a checkpoint with splats (version 5).
  std::vector<tessera::SplatRecord> records(2);
  records[0].paths = 12;
  records[0].odd_paths = 5;
  records[0].entries = {{0, {1, 2, 3, 4}}, {9, {1 << 20, 0, 7, 1 << 10}}, {20, {5, 5, 5, 5}}};
  records[1].paths = 3;
  records[1].entries = {{15, {0, 1, 0, 0}}};
  std::ofstream(fs::path(seeds) / "splats", std::ios::binary)
      << char(6) << char(2) << char(16) << tessera::encode_splats(records);
  tessera::FramePlan splat_plan(checkpoint_settings());
  tessera::FrameSplats splats(checkpoint_settings(), uint32_t(splat_plan.tiles().size()));
  for (int k = 0; k < 5; ++k) {
    const tessera::TileTask t = *splat_plan.take();
    splat_plan.merge(t.tile, t.pass, tile(size_t(t.rect.area())));
    splats.add(t.tile, t.pass, {records[1]});
  }
  std::ofstream(fs::path(seeds) / "checkpoint5splats", std::ios::binary)
      << char(1) << tessera::encode_checkpoint(splat_plan, 2.5, &splats);
  std::exit(0);
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  if (data[0] % 2 == 0) {  // tile sums: two bytes of pixel count, then the payload
    if (size < 3) return 0;
    const size_t pixels = size_t(data[1]) | size_t(data[2]) << 8;
    if (data[0] % 8 == 6) {  // splat records: data[1] % 4 of them, for a frame of data[2] + 1 pixels
      tessera::SplatLimits l;
      l.records = data[1] % 4;
      l.area = uint64_t(data[2]) + 1;
      l.planes = 2;
      l.max_paths = 1000;
      l.max_splats_per_path = 8;
      try {
        const auto records = tessera::decode_splats(std::string(reinterpret_cast<const char*>(data) + 3, size - 3), l);
        if (records.size() != l.records) __builtin_trap();
        tessera::SplatFilm film(tessera::Rect{0, 0, int(l.area), 1}, 64, true);
        for (const tessera::SplatRecord& r : records) film.add_record(r);  // indices within its planes
        tessera::Film f(film.window(), true);
        for (int x = 0; x < film.window().w; ++x) f.at(x, 0) = f.odd_at(x, 0) = {1, 1, 1, 1, 1};
        const tessera::Film folded = film.fold_into(f);  // (kept: a loop over a temporary's pixels would dangle)
        for (const tessera::PixelSums& p : folded.pixels())
          if (!std::isfinite(p.r) || !std::isfinite(p.lum2)) __builtin_trap();
      } catch (const tessera::WireError&) {
      }
      return 0;
    }
    if (data[0] % 4 == 2) {  // AOV sums
      try {
        const auto aovs =
            tessera::decode_aovs(std::string(reinterpret_cast<const char*>(data) + 3, size - 3), pixels, 64);
        if (aovs.size() != pixels) __builtin_trap();
        tessera::AovSums total;
        for (const tessera::AovSums& a : aovs) total.add(a);  // (UBSan: no signed overflow)
        (void)tessera::aov_pixel(total);
      } catch (const tessera::WireError&) {
      }
      return 0;
    }
    try {
      const auto sums = tessera::decode_sums(std::string(reinterpret_cast<const char*>(data) + 3, size - 3), pixels);
      if (sums.size() != pixels) __builtin_trap();
      for (const tessera::PixelSums& p : sums) {
        if (!std::isfinite(p.r) || !std::isfinite(p.g) || !std::isfinite(p.b) || !std::isfinite(p.lum2))
          __builtin_trap();
        (void)tessera::plausible(p);
      }
    } catch (const tessera::WireError&) {
    }
  } else {
    const std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
    try {
      const tessera::Checkpoint c = tessera::decode_checkpoint(bytes);
      if (c.film.pixels().size() != size_t(c.film.window().area())) __builtin_trap();
    } catch (const std::runtime_error&) {
    }
    for (const uint32_t aov_bits : {0u, uint32_t(tessera::kAovAll)}) try {  // into a plan, as a restart reads it
        tessera::RenderSettings s = checkpoint_settings();
        s.aovs = aov_bits;
        tessera::FramePlan plan(s);
        tessera::FrameSplats splats(s, uint32_t(plan.tiles().size()));
        tessera::read_checkpoint(bytes, plan, true, &splats);
        uint64_t n = 0;
        for (const tessera::PixelSums& p : plan.film().pixels()) n += p.n;
        if (n != plan.samples_merged()) __builtin_trap();
        if (aov_bits && plan.aovs().pixels().size() != plan.film().pixels().size()) __builtin_trap();
      } catch (const std::runtime_error&) {
      }
  }
  return 0;
}
