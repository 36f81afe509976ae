// The frame plan: the one schedule of `tessera render` and the coordinator. What it hands
// out, in which order, and what it merges; checked with made-up sums, no rendering.
#include "core/render/frame_plan.h"

#include <gtest/gtest.h>

#include <limits>
#include <set>

namespace tessera {
namespace {

RenderSettings settings(int w, int h, int tile, int spp, int pass) {
  RenderSettings s;
  s.camera.width = w;
  s.camera.height = h;
  s.tile_size = tile;
  s.spp = spp;
  s.pass_spp = pass;
  return s;
}

// Sums as a render of the task would give: every active pixel `pass length` samples of
// radiance `v`.
std::vector<PixelSums> sums_for(const TileTask& t, double v) {
  std::vector<PixelSums> out(size_t(t.rect.area()));
  const uint32_t n = t.sample_end - t.sample_begin;
  for (size_t i = 0; i < out.size(); ++i) {
    if (!t.active.empty() && !t.active[i]) continue;
    out[i] = PixelSums{v * n, v * n, v * n, v * v * n, n};
  }
  return out;
}

TEST(FramePlan, CutsTheWindowIntoTilesAndSamplesIntoPasses) {
  const FramePlan plan(settings(70, 40, 32, 10, 4));
  ASSERT_EQ(plan.tiles().size(), 6u);  // 3 x 2, the last column and row cut short
  EXPECT_EQ(plan.tiles()[2], (Rect{64, 0, 6, 32}));
  EXPECT_EQ(plan.tiles()[5], (Rect{64, 32, 6, 8}));
  ASSERT_EQ(plan.passes().size(), 3u);
  EXPECT_EQ(plan.passes()[2], (std::pair<uint32_t, uint32_t>{8, 10}));
  EXPECT_EQ(plan.samples_total(), 70u * 40u * 10u);
  EXPECT_FALSE(plan.done());
}

// An ended job keeps only its counts (Job::compact): its tiles still read as the frame's.
TEST(FramePlan, ACompactedPlanKeepsItsCountsAndTileGeometry) {
  FramePlan plan(settings(70, 40, 32, 10, 4));
  std::vector<Rect> tiles = plan.tiles();
  while (auto t = plan.take()) ASSERT_EQ(plan.merge(t->tile, t->pass, sums_for(*t, 0.5)), FramePlan::Merge::kMerged);
  ASSERT_TRUE(plan.done());
  const uint64_t samples = plan.samples_merged(), merges = plan.merges();
  plan.compact();
  EXPECT_TRUE(plan.tiles().empty());
  EXPECT_FALSE(plan.has_film());
  EXPECT_TRUE(plan.done());
  EXPECT_EQ(plan.tile_count(), 6u);
  EXPECT_EQ(plan.samples_merged(), samples);
  EXPECT_EQ(plan.merges(), merges);
  for (uint32_t t = 0; t < 6; ++t) {
    EXPECT_EQ(plan.tile_rect(t), tiles[t]) << t;
    EXPECT_TRUE(plan.tile_progress(t).finished);
    EXPECT_EQ(plan.tile_progress(t).passes_done, 3u);
  }
  EXPECT_FALSE(plan.wants(0, 0));
  EXPECT_FALSE(plan.take());
}

TEST(FramePlan, EveryTileOncePerPassFewestPassesFirstAndNoTileTwiceAtOnce) {
  FramePlan plan(settings(64, 64, 16, 12, 4));  // 16 tiles, 3 passes
  std::set<uint32_t> out;
  for (int i = 0; i < 16; ++i) {
    const std::optional<TileTask> t = plan.take();
    ASSERT_TRUE(t);
    EXPECT_EQ(t->pass, 0u);
    EXPECT_TRUE(out.insert(t->tile).second);
  }
  EXPECT_FALSE(plan.take());  // every tile's next pass waits for its previous one
  // Merging tile 5's first pass makes its second ready, and only that.
  TileTask five;
  five.tile = 5;
  five.pass = 0;
  five.rect = plan.tiles()[5];
  five.sample_begin = 0;
  five.sample_end = 4;
  EXPECT_EQ(plan.merge(5, 0, sums_for(five, 1)), FramePlan::Merge::kMerged);
  const std::optional<TileTask> next = plan.take();
  ASSERT_TRUE(next);
  EXPECT_EQ(next->tile, 5u);
  EXPECT_EQ(next->pass, 1u);
  EXPECT_EQ(next->sample_begin, 4u);
  EXPECT_EQ(next->sample_end, 8u);
  EXPECT_FALSE(plan.take());
}

TEST(FramePlan, DuplicatesAndSumsThatDoNotFitChangeNothing) {
  FramePlan plan(settings(32, 32, 16, 8, 4));
  const TileTask t = *plan.take();
  std::vector<PixelSums> wrong_size(3);
  EXPECT_EQ(plan.merge(t.tile, t.pass, wrong_size), FramePlan::Merge::kInvalid);
  std::vector<PixelSums> too_many = sums_for(t, 1);
  too_many[7].n = 5;  // more samples than the pass has
  EXPECT_EQ(plan.merge(t.tile, t.pass, too_many), FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merge(t.tile, 1, sums_for(t, 1)), FramePlan::Merge::kDuplicate);  // not its pass yet
  EXPECT_EQ(plan.merge(99, 0, sums_for(t, 1)), FramePlan::Merge::kDuplicate);      // no such tile
  // Checked beforehand (as a coordinator does outside its lock): for another pass length,
  // or for another tile's size, they still do not fit.
  EXPECT_FALSE(FramePlan::check(too_many, 4));
  EXPECT_EQ(plan.merge(t.tile, t.pass, *FramePlan::check(sums_for(t, 1), 8)), FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merge(t.tile, t.pass, *FramePlan::check(wrong_size, 4)), FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merges(), 0u);
  EXPECT_EQ(plan.samples_merged(), 0u);
  uint64_t samples = 0;
  EXPECT_EQ(plan.merge(t.tile, t.pass, sums_for(t, 1), &samples), FramePlan::Merge::kMerged);
  EXPECT_EQ(samples, 16u * 16u * 4u);
  EXPECT_EQ(plan.merge(t.tile, t.pass, sums_for(t, 1)), FramePlan::Merge::kDuplicate);  // a second copy
  EXPECT_EQ(plan.merges(), 1u);
}

// Issue 10, row 6: a rogue worker's finite but huge sums, or a negative squared luminance,
// were merged and the image had non-finite pixels. No honest render gives either.
TEST(FramePlan, SumsNoRenderCouldGiveAreRefused) {
  FramePlan plan(settings(16, 16, 16, 8, 4));
  const TileTask t = *plan.take();
  auto with = [&](void (*spoil)(PixelSums&)) {
    std::vector<PixelSums> sums = sums_for(t, 0.7);
    spoil(sums[5]);
    return plan.merge(t.tile, t.pass, sums);
  };
  EXPECT_EQ(with([](PixelSums& p) { p.r = 1e300; }), FramePlan::Merge::kInvalid);  // its square cannot fit lum2
  EXPECT_EQ(with([](PixelSums& p) { p.lum2 = -1; }), FramePlan::Merge::kInvalid);
  EXPECT_EQ(with([](PixelSums& p) { p.g = -0.5; }), FramePlan::Merge::kInvalid);
  EXPECT_EQ(with([](PixelSums& p) { p.lum2 = 0.1; }), FramePlan::Merge::kInvalid);  // mean 0.7, spread below 0
  EXPECT_EQ(with([](PixelSums& p) { p.n = 0; }), FramePlan::Merge::kInvalid);       // sums without samples
  EXPECT_EQ(with([](PixelSums& p) { p.b = std::numeric_limits<double>::infinity(); }), FramePlan::Merge::kInvalid);
  // Consistent (Cauchy-Schwarz holds) but brighter than any sample can be: the pixel's
  // mean would not fit the image's floats.
  EXPECT_EQ(with([](PixelSums& p) {
              p = PixelSums{1e150 * p.n, 1e150 * p.n, 1e150 * p.n, 1e300 * p.n, p.n};
            }),
            FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merges(), 0u);
  EXPECT_EQ(with([](PixelSums&) {}), FramePlan::Merge::kMerged);
  for (const PixelSums& p : plan.film().pixels()) EXPECT_TRUE(plausible(p));
}

TEST(FramePlan, AbandonedTasksComeBackAndLateResultsStillCount) {
  FramePlan plan(settings(16, 16, 16, 8, 4));  // one tile
  const TileTask t = *plan.take();
  EXPECT_FALSE(plan.take());
  plan.put_back(t.tile);  // its lease ended
  const std::optional<TileTask> again = plan.take();
  ASSERT_TRUE(again);
  EXPECT_EQ(again->pass, t.pass);
  plan.put_back(t.tile);
  // The first worker's result arrives after all, while the tile waits to be re-issued.
  EXPECT_EQ(plan.merge(t.tile, t.pass, sums_for(t, 1)), FramePlan::Merge::kMerged);
  const std::optional<TileTask> second = plan.take();  // the next pass, not the old one
  ASSERT_TRUE(second);
  EXPECT_EQ(second->pass, 1u);
  EXPECT_FALSE(plan.take());
  EXPECT_EQ(plan.merge(second->tile, 1, sums_for(*second, 1)), FramePlan::Merge::kMerged);
  EXPECT_TRUE(plan.done());
  EXPECT_EQ(plan.fraction_done(), 1);
  EXPECT_EQ(plan.frame_passes_done(), 2u);
  plan.put_back(t.tile);  // a lease that ends after the tile finished changes nothing
  EXPECT_FALSE(plan.take());
}

// Converged pixels leave the active mask; a tile with none left is finished early.
TEST(FramePlan, AdaptiveSamplingMasksConvergedPixelsAndFinishesTilesEarly) {
  RenderSettings s = settings(16, 8, 8, 64, 1);
  s.adaptive = true;
  s.adaptive_batch = 4;  // passes [0,5) [5,9) ...
  s.adaptive_tolerance = 0.05f;
  FramePlan plan(s);
  for (int k = 0; k < 2; ++k) {
    const TileTask t = *plan.take();
    ASSERT_EQ(t.active.size(), 64u);
    std::vector<PixelSums> sums = sums_for(t, 1);  // zero variance: converged at once
    if (t.tile == 1) sums[3].lum2 *= 3;            // one noisy pixel keeps tile 1 going
    EXPECT_EQ(plan.merge(t.tile, t.pass, sums), FramePlan::Merge::kMerged);
  }
  EXPECT_TRUE(plan.progress(0).finished);
  EXPECT_FALSE(plan.progress(1).finished);
  const TileTask t = *plan.take();
  EXPECT_EQ(t.tile, 1u);
  EXPECT_EQ(t.sample_begin, 5u);
  for (size_t i = 0; i < t.active.size(); ++i) EXPECT_EQ(t.active[i], i == 3 ? 1 : 0) << i;
  EXPECT_FALSE(plan.take());
}

// A tile stops once its estimated relative error meets the target, after two passes.
TEST(FramePlan, NoiseTargetFinishesQuietTilesAfterTwoPasses) {
  RenderSettings s = settings(16, 8, 8, 64, 4);
  s.noise_target = 0.1;
  FramePlan plan(s);
  auto run_pass = [&](double quiet_noise, double loud_noise) {
    for (int k = 0; k < 2; ++k) {
      const TileTask t = *plan.take();
      std::vector<PixelSums> sums = sums_for(t, 1);
      const double noise = t.tile == 0 ? quiet_noise : loud_noise;
      for (PixelSums& p : sums) p.lum2 += noise * p.n;  // per-sample variance ~ noise
      ASSERT_EQ(plan.merge(t.tile, t.pass, sums), FramePlan::Merge::kMerged);
    }
  };
  run_pass(0, 10);
  EXPECT_FALSE(plan.progress(0).finished);  // quiet, but only one pass
  run_pass(0, 10);
  EXPECT_TRUE(plan.progress(0).finished);
  EXPECT_LE(plan.progress(0).relative_error, 0.1f);
  EXPECT_FALSE(plan.progress(1).finished);
  EXPECT_GT(plan.progress(1).relative_error, 0.1f);
  EXPECT_LT(plan.fraction_done(), 1);
}

// Sums with some noise that depends on the task and pixel only, so that adaptive sampling
// stops some pixels and not others.
std::vector<PixelSums> noisy_sums_for(const TileTask& t) {
  std::vector<PixelSums> out = sums_for(t, 0.5);
  for (size_t i = 0; i < out.size(); ++i) {
    const uint32_t h = uint32_t((t.tile * 7919u + t.pass * 104729u + uint32_t(i) * 2654435761u) >> 7) % 97;
    out[i].lum2 += out[i].n * (h < 40 ? 0.0 : 0.01 * h);
  }
  return out;
}

// Settings whose tiles take several passes, with and without adaptive sampling.
RenderSettings noisy_settings(bool adaptive) {
  RenderSettings s = settings(40, 24, 8, 24, 4);
  s.adaptive = adaptive;
  s.adaptive_batch = 4;
  s.adaptive_tolerance = 0.2f;
  return s;
}

// Every pixel's sums equal bit for bit (field by field: PixelSums has padding).
void expect_same_film(const Film& a, const Film& b) {
  ASSERT_EQ(a.pixels().size(), b.pixels().size());
  for (size_t i = 0; i < a.pixels().size(); ++i) {
    const PixelSums &p = a.pixels()[i], &q = b.pixels()[i];
    ASSERT_TRUE(p.r == q.r && p.g == q.g && p.b == q.b && p.lum2 == q.lum2 && p.n == q.n) << i;
  }
}

// A plan rebuilt from state() and film() goes on exactly as the plan it was taken from:
// the same tasks in the same order, the same film bits, the same progress. This is what
// lets a restarted coordinator finish a job bit-identical to `tessera render`.
TEST(FramePlan, ARestoredPlanGoesOnExactlyAsTheOriginal) {
  for (const bool adaptive : {false, true}) {
    const RenderSettings s = noisy_settings(adaptive);
    FramePlan a(s);
    for (int k = 0; k < 23; ++k) {  // part of the way, with one task left taken
      const TileTask t = *a.take();
      ASSERT_EQ(a.merge(t.tile, t.pass, noisy_sums_for(t)), FramePlan::Merge::kMerged);
    }
    (void)a.take();  // taken when the checkpoint is written: the restored plan hands it out again
    FramePlan b(s);
    b.restore(a.state(), a.film());
    EXPECT_EQ(b.merges(), a.merges());
    EXPECT_EQ(b.samples_merged(), a.samples_merged());
    EXPECT_EQ(b.frame_passes_done(), a.frame_passes_done());
    EXPECT_EQ(b.tiles_done(), a.tiles_done());
    EXPECT_EQ(b.fraction_done(), a.fraction_done());
    FramePlan progress_only(s);  // an ended job's, restored without its film
    progress_only.restore(a.state(), Film(Rect{}));
    EXPECT_FALSE(progress_only.has_film());
    EXPECT_EQ(progress_only.samples_merged(), a.samples_merged());
    EXPECT_EQ(progress_only.tiles_done(), a.tiles_done());
    // `a` restarted too (its taken task lost with the coordinator), then both run to the end.
    FramePlan a2(s);
    a2.restore(a.state(), a.film());
    int steps = 0;
    while (!a2.done()) {
      const std::optional<TileTask> ta = a2.take(), tb = b.take();
      ASSERT_TRUE(ta && tb);
      ASSERT_EQ(ta->tile, tb->tile);
      ASSERT_EQ(ta->pass, tb->pass);
      ASSERT_EQ(ta->active, tb->active);
      ASSERT_EQ(a2.merge(ta->tile, ta->pass, noisy_sums_for(*ta)), FramePlan::Merge::kMerged);
      ASSERT_EQ(b.merge(tb->tile, tb->pass, noisy_sums_for(*tb)), FramePlan::Merge::kMerged);
      ++steps;
    }
    EXPECT_GT(steps, 0);
    EXPECT_TRUE(b.done());
    expect_same_film(a2.film(), b.film());
    for (uint32_t t = 0; t < b.tiles().size(); ++t) {
      EXPECT_EQ(a2.progress(t).passes_done, b.progress(t).passes_done);
      EXPECT_EQ(a2.progress(t).relative_error, b.progress(t).relative_error);
    }
  }
}

// Band by band (what the coordinator's snapshots do: a few rows under its lock at a time,
// no second film): copies taken while the plan keeps merging, so each band comes from
// another moment, restored into a fresh plan, finish with the film and progress the
// original finishes with. Each tile's sums and progress are copied together, and every
// counter follows from the tiles.
TEST(FramePlan, BandsCopiedWhileMergingRestoreAPlanThatFinishesAsTheOriginal) {
  for (const bool adaptive : {false, true}) {
    const RenderSettings s = noisy_settings(adaptive);
    FramePlan a(s);
    auto step = [&](int n) {
      for (int k = 0; k < n && !a.done(); ++k) {
        const TileTask t = *a.take();
        ASSERT_EQ(a.merge(t.tile, t.pass, noisy_sums_for(t)), FramePlan::Merge::kMerged);
      }
    };
    step(23);
    ASSERT_GE(a.bands(), 2u);
    EXPECT_EQ(a.bands() * a.tiles_per_band(), a.tiles().size());
    std::vector<BandCopy> copies(a.bands());
    for (uint32_t b = 0; b < a.bands(); ++b) {
      a.copy_band(b, &copies[b]);
      step(3);  // the plan moves on between bands
    }
    FramePlan r(s);
    for (uint32_t b = a.bands(); b-- > 0;) r.restore_band(copies[b]);  // any order
    r.restore_finish();
    uint64_t n = 0;
    for (const PixelSums& p : r.film().pixels()) n += p.n;
    EXPECT_EQ(r.samples_merged(), n);
    int steps = 0;
    for (; !r.done(); ++steps) {
      const TileTask t = *r.take();
      ASSERT_EQ(r.merge(t.tile, t.pass, noisy_sums_for(t)), FramePlan::Merge::kMerged);
    }
    step(100000);
    ASSERT_TRUE(a.done());
    EXPECT_GT(steps, 0);
    expect_same_film(a.film(), r.film());
    for (uint32_t t = 0; t < a.tiles().size(); ++t) {
      EXPECT_EQ(a.progress(t).passes_done, r.progress(t).passes_done);
      EXPECT_EQ(a.progress(t).relative_error, r.progress(t).relative_error);
    }
    EXPECT_EQ(r.samples_merged(), a.samples_merged());
    EXPECT_EQ(r.fraction_done(), 1.0);
  }
}

// A plan restored band by band at one moment has the original's counters.
TEST(FramePlan, BandsRestoreTheCountersTheyImply) {
  const RenderSettings s = noisy_settings(true);
  FramePlan a(s);
  for (int k = 0; k < 31; ++k) {
    const TileTask t = *a.take();
    ASSERT_EQ(a.merge(t.tile, t.pass, noisy_sums_for(t)), FramePlan::Merge::kMerged);
  }
  FramePlan r(s);
  BandCopy band;
  for (uint32_t b = 0; b < a.bands(); ++b) {
    a.copy_band(b, &band);
    r.restore_band(band);
  }
  r.restore_finish();
  EXPECT_EQ(r.samples_merged(), a.samples_merged());
  EXPECT_EQ(r.tiles_done(), a.tiles_done());
  EXPECT_EQ(r.frame_passes_done(), a.frame_passes_done());
  EXPECT_EQ(r.ready(), a.ready() + 0);
  EXPECT_NEAR(r.fraction_done(), a.fraction_done(), 1e-12);
  expect_same_film(a.film(), r.film());
  band.progress.pop_back();  // a band that does not fit
  EXPECT_THROW(r.restore_band(band), std::invalid_argument);
}

TEST(FramePlan, AStateThatDoesNotFitIsRefusedAndChangesNothing) {
  const RenderSettings s = settings(40, 24, 8, 24, 4);
  FramePlan a(s);
  const TileTask t = *a.take();
  ASSERT_EQ(a.merge(t.tile, t.pass, sums_for(t, 1)), FramePlan::Merge::kMerged);
  FramePlan b(s);
  PlanState st = a.state();
  st.progress.pop_back();
  EXPECT_THROW(b.restore(st, a.film()), std::invalid_argument);
  st = a.state();
  st.progress[0].passes_done = 99;
  EXPECT_THROW(b.restore(st, a.film()), std::invalid_argument);
  EXPECT_THROW(b.restore(a.state(), Film(Rect{0, 0, 8, 8})), std::invalid_argument);
  st = a.state();
  st.active.assign(10, 1);  // a mask for a plan without adaptive sampling
  EXPECT_THROW(b.restore(st, a.film()), std::invalid_argument);
  EXPECT_EQ(b.merges(), 0u);
  EXPECT_EQ(b.ready(), b.tiles().size());
}

// A tile reset (its results came from a lying worker) and rendered again ends with the
// film of a plan that never saw the lie.
TEST(FramePlan, AResetTileRenderedAgainGivesTheHonestFilm) {
  for (const bool adaptive : {false, true}) {
    const RenderSettings s = noisy_settings(adaptive);
    FramePlan honest(s), lied_to(s);
    while (!honest.done()) {
      const TileTask t = *honest.take();
      ASSERT_EQ(honest.merge(t.tile, t.pass, noisy_sums_for(t)), FramePlan::Merge::kMerged);
    }
    std::set<uint32_t> lied;  // tiles with a lie merged: tile 3 and 7, on their second pass
    while (!lied_to.done()) {
      const TileTask t = *lied_to.take();
      std::vector<PixelSums> sums = noisy_sums_for(t);
      if ((t.tile == 3 || t.tile == 7) && t.pass == 1 && !lied.count(t.tile)) {
        for (PixelSums& p : sums)
          p = PixelSums{p.r * 0.8, p.g * 0.8, p.b * 0.8, p.lum2 * 0.64, p.n};  // plausible, wrong
        lied.insert(t.tile);
      }
      ASSERT_EQ(lied_to.merge(t.tile, t.pass, sums), FramePlan::Merge::kMerged);
      if (lied.size() == 2 && lied_to.merges() >= 32) {  // the lies found after some more merges
        for (uint32_t bad : {3u, 7u}) lied_to.reset_tile(bad);
        lied.insert(99);
        EXPECT_FALSE(lied_to.done());
        EXPECT_EQ(lied_to.progress(3).passes_done, 0u);
      }
    }
    ASSERT_TRUE(lied.count(99));
    expect_same_film(honest.film(), lied_to.film());
    EXPECT_EQ(honest.samples_merged(), lied_to.samples_merged());
    EXPECT_EQ(lied_to.fraction_done(), 1);
  }
}

}  // namespace
}  // namespace tessera
