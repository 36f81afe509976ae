// Light paths through the farm (issue 28): a task's light paths land anywhere in the frame;
// their splats travel with its sums as fixed-point records and the coordinator adds them to
// the frame's splat film, so the farm's EXR is tessera render's bit for bit at every split
// (runs of passes, half-buffers), and a coordinator killed mid-job keeps them (its
// checkpoints freeze the splats after the bands: frame_splats.h).
#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

const std::string kSplatFlags = kFlags + " --light-tracer on";

TEST_F(Farm, SplatsMakeTheLocalImageAtEverySplit) {
  const std::string local = local_render(kSplatFlags);
  start_coordinator();
  start_worker();
  start_worker(2, {"--passes-per-task", "3"});  // runs of passes: a record per pass
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, kSplatFlags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
  // And the light paths made a difference: the same frame without them is another image.
  const std::string off = (dir / "off.exr").string();
  ASSERT_EQ(run("render " + kScene + " " + kFlags + " --light-tracer off -q -f " + off, dir).code, 0);
  const ExrImage a = read_exr(local), b = read_exr(off);
  EXPECT_NE(a.channels.at("R"), b.channels.at("R"));
}

TEST_F(Farm, AutoChoosesAsTesseraRenderDoesAndHalvesGetTheirOwnLightPaths) {
  const std::string flags = kFlags + " --light-tracer auto --aov halves";
  const std::string local = local_render(flags);
  start_coordinator();
  start_worker(2);
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, flags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
}

// Passes of 3 samples in a column one pixel wide: a pixel traces a light path in each
// aligned block of 4 samples, so a pass that straddles two blocks holds two of some pixels'
// (here of all of them: every pixel of column 47 of a 96-wide image has the same pick), and
// LightTracer::max_paths_per_pixel bounds what the coordinator accepts. Each half gets its own.
TEST_F(Farm, PassesAcrossLightPathBlocksMakeTheLocalImage) {
  const std::string flags =
      "-r 96 72 -p 47 0 1 72 -s 24 --pass-spp 3 -m 6 --seed 11 --tile 16 --light-tracer on --aov halves";
  const std::string local = local_render(flags);
  start_coordinator();
  start_worker(2);
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, flags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);   // (their data windows too)
  EXPECT_EQ(read_exr(out).x0, 47);  // the column in its place in the frame
}

TEST_F(Farm, SplatsSurviveACoordinatorKilledMidJob) {
  const std::string flags = "-r 96 72 -s 512 --pass-spp 8 -m 6 --seed 5 --light-tracer on --aov halves";
  const std::string local = local_render(flags);
  const std::vector<std::string> crashy{"--checkpoint-seconds", "0.2"};
  start_coordinator("127.0.0.1:0", "2", crashy);
  const std::string out = (dir / "farm.exr").string();
  const std::unique_ptr<Process> client = submit_in_background(flags, out);
  start_worker();
  start_worker(1, {"--passes-per-task", "4"});
  // Twice: once some of it is merged and checkpointed, killed and started again on its folder.
  for (const uint64_t above : {uint64_t(0), uint64_t(100000)}) {
    crash_coordinator_mid_job(above, crashy);
    ASSERT_FALSE(HasFatalFailure());
  }
  ASSERT_EQ(client->wait(180), 0) << slurp((dir / "client.err").string());
  expect_same_pixels(local, out);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// A light of radiance 1.2e8: its splats enter their sums scaled down by 2^splat_exponent
// (they passed the 2^20 cap and were dropped: 7% dark). The coordinator sets the exponent
// at submit from its copy of the scene, the workers use it, its fold scales them back: the
// farm's image is still tessera render's, bit for bit.
TEST_F(Farm, ABrightLightsSplatsMakeTheLocalImage) {
  std::string text = slurp(kScene);
  for (size_t at; (at = text.find("12 12 12")) != std::string::npos;) text.replace(at, 8, "1.2e8 1.2e8 1.2e8");
  const std::string scene = (dir / "bright.dae").string();
  std::ofstream(scene) << text;
  const std::string local = (dir / "local.exr").string(), out = (dir / "farm.exr").string();
  const CommandResult l = run("render " + scene + " " + kSplatFlags + " -f " + local, dir);
  ASSERT_EQ(l.code, 0) << l.err;
  EXPECT_EQ(l.err.find("dropped"), std::string::npos) << l.err;
  start_coordinator();
  start_worker();
  start_worker(2);
  const CommandResult r = submit_wait(scene, kSplatFlags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
}

}  // namespace
}  // namespace tessera
