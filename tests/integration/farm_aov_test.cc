// AOVs through the farm (issue 26): every layer of the farm's EXR is tessera render's, bit
// for bit, whatever the workers (runs of passes included), and a coordinator killed mid-job
// keeps them (they are in its checkpoints).
#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

const std::string kAovFlags = kFlags + " --aov all";

TEST_F(Farm, AovLayersAreTheLocalRendersBitForBit) {
  const std::string local = local_render(kAovFlags);
  start_coordinator();
  start_worker();
  start_worker(2, {"--passes-per-task", "3"});  // runs of passes: AOV sums of several at once
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, kAovFlags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
  const ExrImage img = read_exr(out);
  for (const char* ch :
       {"A", "albedo.R", "albedo.G", "albedo.B", "normal.X", "normal.Y", "normal.Z", "depth.Z", "id.V"})
    EXPECT_TRUE(img.channels.count(ch)) << ch;
}

// --denoise: the coordinator denoises the final image from the same float layers tessera
// render denoises, so the denoised image, the noisy one kept beside it and the half-buffers
// are the local render's, bit for bit (runs of passes carry the second plane of sums too).
TEST_F(Farm, DenoisedFinalIsTheLocalRendersBitForBit) {
  const std::string flags = kFlags + " --denoise";
  const std::string local = local_render(flags);
  start_coordinator();
  start_worker();
  start_worker(2, {"--passes-per-task", "3"});
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, flags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
  const ExrImage img = read_exr(out);
  for (const char* ch : {"noisy.R", "noisy.G", "noisy.B", "even.R", "odd.B", "albedo.G", "normal.Z", "depth.Z"})
    EXPECT_TRUE(img.channels.count(ch)) << ch;
  EXPECT_EQ(img.metadata.count("tessera/denoiser"), 1u);
  EXPECT_NE(img.channels.at("R"), img.channels.at("noisy.R"));          // it was denoised
  for (const auto& e : fs::recursive_directory_iterator(dir / "data"))  // the noisy file went once denoised
    EXPECT_EQ(e.path().string().find("noisy"), std::string::npos) << e.path();
}

TEST_F(Farm, AovsSurviveACoordinatorKilledMidJob) {
  // The half-buffers too: the film's second plane is in the checkpoints.
  const std::string flags = "-r 96 72 -s 512 --pass-spp 8 -m 6 --seed 5 --aov all,halves";
  const std::string local = local_render(flags);
  const std::vector<std::string> crashy{"--checkpoint-seconds", "0.2"};
  start_coordinator("127.0.0.1:0", "2", crashy);
  const std::string out = (dir / "farm.exr").string();
  const std::unique_ptr<Process> client = submit_in_background(flags, out);
  start_worker();
  // Once some of it is merged and checkpointed: killed, and started again on its folder; it
  // goes on from its checkpoint (AOVs included: restore_band refuses a band without them).
  crash_coordinator_mid_job(0, crashy);
  ASSERT_FALSE(HasFatalFailure());
  ASSERT_EQ(client->wait(120), 0) << slurp((dir / "client.err").string());
  expect_same_pixels(local, out);
}

}  // namespace
}  // namespace tessera
