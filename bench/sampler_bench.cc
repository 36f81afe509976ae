// The sampler's draws: one dimension at a time (Sampler::value_at, how every draw was
// computed before the batches) against the batches Sampler draws from (AVX2 where the CPU
// has it), in the pattern of a path: per sample four vertices of a 2D light sample, a 1D
// lobe choice, a 2D direction and a 1D roulette decision. Both give the same bits
// (tests/core/sampling_test.cc); this measures their cost.
//
// Usage: tessera_sampler_bench [Google Benchmark flags]
#include <benchmark/benchmark.h>

#include "core/sampling/sampler.h"

using namespace tessera;

namespace {

constexpr int kVertices = 4;  // vertices a sample, each drawing four dimensions

void BM_DrawsOneAtATime(benchmark::State& state) {
  uint32_t sample = 0;
  for (auto _ : state) {
    const uint64_t key = Sampler::pixel_key(7, sample);
    const uint32_t reversed = reverse_bits(sample & 1023);
    uint32_t d = 0;
    float acc = 0;
    for (int v = 0; v < kVertices; ++v) {
      const Vec2 light = Sampler::value_at(key, reversed, ++d);
      const float lobe = Sampler::value_at(key, reversed, ++d).x;
      const Vec2 dir = Sampler::value_at(key, reversed, ++d);
      const float roulette = Sampler::value_at(key, reversed, ++d).x;
      acc += light.x + light.y + lobe + dir.x + dir.y + roulette;
    }
    benchmark::DoNotOptimize(acc);
    ++sample;
  }
  state.SetItemsProcessed(state.iterations() * kVertices * 4);
}
BENCHMARK(BM_DrawsOneAtATime);

void BM_DrawsBatched(benchmark::State& state) {
  uint32_t sample = 0;
  for (auto _ : state) {
    Sampler s(7, sample, sample & 1023);
    float acc = 0;
    for (int v = 0; v < kVertices; ++v) {
      const Vec2 light = s.next_2d();
      const float lobe = s.next_1d();
      const Vec2 dir = s.next_2d();
      acc += light.x + light.y + lobe + dir.x + dir.y + s.next_1d();
    }
    benchmark::DoNotOptimize(acc);
    ++sample;
  }
  state.SetItemsProcessed(state.iterations() * kVertices * 4);
}
BENCHMARK(BM_DrawsBatched);

// One batch of four dimensions, each implementation.
template <bool kAvx2>
void BM_Fill(benchmark::State& state) {
  float x[sampler_batch::kDimensions], y[sampler_batch::kDimensions];
  if (kAvx2 && !sampler_batch::fill_avx2(0, 0, 0, x, y)) {
    state.SkipWithError("this CPU has no AVX2");
    return;
  }
  uint32_t d = 0;
  for (auto _ : state) {
    if constexpr (kAvx2)
      sampler_batch::fill_avx2(0x1234567887654321ull, 0x9abcdef0u, d += 4, x, y);
    else
      sampler_batch::fill_scalar(0x1234567887654321ull, 0x9abcdef0u, d += 4, x, y);
    benchmark::DoNotOptimize(x);
    benchmark::DoNotOptimize(y);
  }
  state.SetItemsProcessed(state.iterations() * sampler_batch::kDimensions);
}
BENCHMARK(BM_Fill<false>)->Name("BM_FillScalar");
BENCHMARK(BM_Fill<true>)->Name("BM_FillAvx2");

}  // namespace

BENCHMARK_MAIN();
