// The cost of a tile's sums on the wire: encode_sums on the worker, decode_sums on the
// coordinator (where every merged result pays it), for a 32x32 tile and a 1920x1080 film
// in one piece; and a coordinator's checkpoint of a 1920x1080 and a 480x360 film (the
// sums in pieces), written and read. Google Benchmark; --benchmark_repetitions=N for
// spreads.
#include <benchmark/benchmark.h>

#include <random>

#include "proto/wire.h"
#include "server/checkpoint.h"
#include "server/job_store.h"

using namespace tessera;

namespace {
// Sums as a render gives them: `spp` float samples a pixel, so the doubles' low bytes are
// mostly zero, with a few fireflies.
std::vector<PixelSums> render_like(size_t pixels, int spp) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<PixelSums> sums(pixels);
  for (PixelSums& p : sums)
    for (int s = 0; s < spp; ++s) {
      const float k = u(rng) < 0.01f ? 20.0f : 1.0f;
      const float r = k * u(rng), g = k * u(rng), b = k * u(rng);
      const float l = 0.2126f * r + 0.7152f * g + 0.0722f * b;
      p.add(PixelSums{r, g, b, double(l) * l, 1});
    }
  return sums;
}

void Encode(benchmark::State& state) {
  const auto sums = render_like(size_t(state.range(0)), int(state.range(1)));
  size_t bytes = 0;
  for (auto _ : state) {
    const std::string e = encode_sums(sums);
    bytes = e.size();
    benchmark::DoNotOptimize(e.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
  state.counters["ratio"] = double(bytes) / double(sums.size() * kBytesPerPixel);
}

void Decode(benchmark::State& state) {
  const auto sums = render_like(size_t(state.range(0)), int(state.range(1)));
  const std::string e = encode_sums(sums);
  for (auto _ : state) {
    auto d = decode_sums(e, sums.size());
    benchmark::DoNotOptimize(d.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}

// A plan whose film holds render-like sums, as a checkpoint of it is written band by band
// (the current version, checkpoint.h) and read back into a plan.
void CheckpointFilm(benchmark::State& state) {
  RenderSettings s;
  s.camera.width = int(state.range(1));
  s.camera.height = int(state.range(2));
  FramePlan plan(s);
  const auto sums = render_like(size_t(s.camera.width) * size_t(s.camera.height), 16);
  BandCopy band;
  for (uint32_t b = 0; b < plan.bands(); ++b) {
    plan.copy_band(b, &band);
    std::copy_n(sums.begin() + ptrdiff_t(size_t(band.y0) * size_t(band.width)), band.pixels.size(),
                band.pixels.begin());
    plan.restore_band(band);
  }
  plan.restore_finish();
  for (auto _ : state) {
    const std::string bytes = encode_checkpoint(plan, 1);
    benchmark::DoNotOptimize(bytes.data());
    if (state.range(0)) {
      FramePlan back(s);
      read_checkpoint(bytes, back);
      benchmark::DoNotOptimize(back.film().pixels().data());
    }
  }
  state.SetItemsProcessed(state.iterations() * int64_t(sums.size()));
}
}  // namespace

// A 32x32 tile of 1 and of 16 samples a pixel; a 1080p film (a checkpoint's sums).
BENCHMARK(Encode)->Args({1024, 1})->Args({1024, 16})->Args({1920 * 1080, 16})->Unit(benchmark::kMicrosecond);
BENCHMARK(Decode)->Args({1024, 1})->Args({1024, 16})->Args({1920 * 1080, 16})->Unit(benchmark::kMicrosecond);
// A checkpoint written (0), written and read back (1), of a 1920x1080 and a 480x360 film.
BENCHMARK(CheckpointFilm)
    ->Args({0, 1920, 1080})
    ->Args({1, 1920, 1080})
    ->Args({0, 480, 360})
    ->Args({1, 480, 360})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
