// Runs of passes (FramePlan::take with max_passes > 1): a task of several passes of a tile,
// from its first pass or from its sums so far, whose result takes the tile's place. What a
// worker on a slow link asks for; the film's bits must not change.
#include <gtest/gtest.h>

#include "core/render/frame_plan.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "test_paths.h"

namespace tessera {
namespace {

RenderSettings small_frame() {
  RenderSettings s;
  s.camera.width = 40;
  s.camera.height = 24;
  s.tile_size = 16;
  s.spp = 14;
  s.pass_spp = 3;  // passes of 3, 3, 3, 3 and 2 samples
  s.max_depth = 4;
  s.light_tracer = RenderSettings::LightTracer::kOff;  // the path tracer's tiles (light paths: light_tracer_test)
  return s;
}

// Renders a frame through a plan as a farm would, one task at a time, asking for runs of
// `runs[i % size]` passes: what each task's result is, and how it is merged, as the
// coordinator and worker do it.
Film render_in_runs(const TileRenderer& r, const std::vector<uint32_t>& runs, size_t* run_tasks) {
  FramePlan plan(r.settings());
  size_t i = 0;
  *run_tasks = 0;
  while (!plan.done()) {
    std::optional<TileTask> t = plan.take(runs[i++ % runs.size()]);
    EXPECT_TRUE(t.has_value());
    if (!t) break;
    TileStats stats;
    const auto passes = pass_run(r.settings(), t->pass, t->pass_count);
    EXPECT_EQ(passes.front().first, t->sample_begin);
    EXPECT_EQ(passes.back().second, t->sample_end);
    std::optional<CheckedSums> sums =
        FramePlan::check(r.render_passes(t->rect, passes, t->base.empty() ? nullptr : t->base.data(), nullptr, &stats),
                         plan.run_samples(t->pass, t->pass_count));
    EXPECT_TRUE(sums.has_value());
    if (!sums) break;
    uint64_t added = 0;
    EXPECT_EQ(plan.merge(t->tile, t->pass, *sums, t->pass_count, &added), FramePlan::Merge::kMerged);
    EXPECT_EQ(added, uint64_t(t->sample_end - t->sample_begin) * uint64_t(t->rect.area()));
    *run_tasks += t->pass_count > 1;
  }
  EXPECT_EQ(plan.samples_merged(), plan.samples_total());
  return plan.film();
}

TEST(PassRuns, RunsFromTheFirstPassOrFromATilesSumsGiveTheFilmsBits) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  const TileRenderer r(scene, small_frame());
  const Film local = render_image(r, 2).film;
  // Whole tiles, runs of two from any pass (after a single pass, with the sums so far),
  // and a mix: every film bit for bit as `tessera render`'s.
  for (const std::vector<uint32_t>& runs : std::vector<std::vector<uint32_t>>{{64}, {2}, {1, 2}, {1, 3, 1, 2}}) {
    size_t run_tasks = 0;
    const Film film = render_in_runs(r, runs, &run_tasks);
    EXPECT_GT(run_tasks, 0u);
    ASSERT_EQ(film.pixels().size(), local.pixels().size());
    for (size_t i = 0; i < film.pixels().size(); ++i) {
      const PixelSums &p = film.pixels()[i], &q = local.pixels()[i];
      ASSERT_TRUE(p.r == q.r && p.g == q.g && p.b == q.b && p.lum2 == q.lum2 && p.n == q.n)
          << "pixel " << i << " with runs of " << runs[0];
    }
  }
}

TEST(PassRuns, ATaskIsARunOfPassesOnlyWhereNothingIsDecidedBetweenPasses) {
  RenderSettings s = small_frame();
  FramePlan plain(s);
  const TileTask whole = *plain.take(64);
  EXPECT_EQ(whole.pass_count, 5u);
  EXPECT_EQ(whole.sample_begin, 0u);
  EXPECT_EQ(whole.sample_end, 14u);
  EXPECT_TRUE(whole.base.empty());  // from the first pass: nothing so far
  EXPECT_EQ(plain.run_samples(0, 5), 14u);
  EXPECT_EQ(plain.run_samples(1, 2), 9u);  // a run's result holds the tile's sums: all samples until its end
  EXPECT_EQ(plain.run_samples(4, 1), 2u);  // one pass: that pass's
  EXPECT_EQ(plain.run_samples(4, 2), 0u);  // past the last pass
  EXPECT_EQ(plain.run_samples(0, 0), 0u);

  s.noise_target = 0.01;  // decided after each pass from the merged film: no runs
  FramePlan quiet(s);
  EXPECT_EQ(quiet.take(64)->pass_count, 1u);
  EXPECT_EQ(quiet.run_samples(0, 2), 0u);
  s.noise_target = 0;
  s.adaptive = true;
  FramePlan adaptive(s);
  EXPECT_EQ(adaptive.take(64)->pass_count, 1u);
  EXPECT_EQ(adaptive.run_samples(0, 2), 0u);
}

// Sums as a run would give them for every pixel of a tile: `n` samples of radiance v.
std::vector<PixelSums> flat(const TileTask& t, uint32_t n, double v) {
  return std::vector<PixelSums>(size_t(t.rect.area()), PixelSums{v * n, v * n, v * n, v * v * n, n});
}

// Takes tasks until one is of `tile` (the others stay taken); nothing if none is.
std::optional<TileTask> take_tile(FramePlan& plan, uint32_t tile, uint32_t max_passes) {
  for (uint32_t i = 0; i <= plan.tile_count(); ++i)
    if (std::optional<TileTask> t = plan.take(max_passes); !t || t->tile == tile) return t;
  return std::nullopt;
}

TEST(PassRuns, ARunThatDoesNotHoldTheTilesSumsOrComesLateChangesNothing) {
  FramePlan plan(small_frame());
  // One pass of tile 0, then a run of the rest from its sums.
  const TileTask first = *plan.take();
  ASSERT_EQ(plan.merge(first.tile, first.pass, *FramePlan::check(flat(first, 3, 1.0), 3)), FramePlan::Merge::kMerged);
  std::optional<TileTask> run = take_tile(plan, first.tile, 8);
  ASSERT_TRUE(run.has_value());
  ASSERT_EQ(run->pass, 1u);
  ASSERT_EQ(run->pass_count, 4u);
  ASSERT_EQ(run->base.size(), size_t(run->rect.area()));
  EXPECT_EQ(run->base[0].n, 3u);
  const uint64_t merged = plan.samples_merged();
  const Film before = plan.film();
  auto same_as_before = [&] {
    EXPECT_EQ(plan.samples_merged(), merged);
    EXPECT_EQ(plan.progress(first.tile).passes_done, 1u);
    for (size_t i = 0; i < before.pixels().size(); ++i) ASSERT_EQ(plan.film().pixels()[i].r, before.pixels()[i].r);
  };
  // Fewer samples or smaller sums than the tile has: not a run from its sums.
  EXPECT_EQ(plan.merge(run->tile, 1, *FramePlan::check(flat(*run, 2, 9.0), 14), 4), FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merge(run->tile, 1, *FramePlan::check(flat(*run, 14, 0.1), 14), 4), FramePlan::Merge::kInvalid);
  // Checked for another length, or a run past the last pass.
  EXPECT_EQ(plan.merge(run->tile, 1, *FramePlan::check(flat(*run, 14, 1.0), 15), 4), FramePlan::Merge::kInvalid);
  EXPECT_EQ(plan.merge(run->tile, 1, *FramePlan::check(flat(*run, 14, 1.0), 14), 5), FramePlan::Merge::kInvalid);
  same_as_before();
  // A backup of pass 1 alone came first: the run is then a duplicate.
  const TileTask backup = *plan.retake(run->tile);
  EXPECT_EQ(backup.pass_count, 1u);
  ASSERT_EQ(plan.merge(backup.tile, 1, *FramePlan::check(flat(backup, 3, 1.0), 3)), FramePlan::Merge::kMerged);
  EXPECT_EQ(plan.merge(run->tile, 1, *FramePlan::check(flat(*run, 14, 1.0), 14), 4), FramePlan::Merge::kDuplicate);
  EXPECT_EQ(plan.progress(first.tile).passes_done, 2u);
  // A run that holds the tile's sums is merged in their place and counts only what it added.
  std::optional<TileTask> rest = take_tile(plan, first.tile, 8);
  ASSERT_TRUE(rest.has_value());
  ASSERT_EQ(rest->pass, 2u);
  uint64_t added = 0;
  ASSERT_EQ(plan.merge(rest->tile, 2, *FramePlan::check(flat(*rest, 14, 1.0), 14), 3, &added),
            FramePlan::Merge::kMerged);
  EXPECT_EQ(added, uint64_t(8) * uint64_t(rest->rect.area()));
  EXPECT_TRUE(plan.progress(first.tile).finished);
  EXPECT_EQ(plan.film().pixels()[0].n, 14u);
}

}  // namespace
}  // namespace tessera
