// Admission: what a submit asks for, checked before anything is allocated (admit), and the
// limits on live work it would pass (over_limit).
#include "server/admission.h"

#include <gtest/gtest.h>

#include <limits>

#include "core/render/frames.h"
#include "scene_chunks.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::has;
using testing::refusal;
using testing::small_settings;
constexpr auto kInvalid = RequestError::Code::kInvalidArgument;

// A request with one 100-byte scene file named "scene.dae" (9 bytes of path).
v1::SubmitJobRequest request(const RenderSettings& s = small_settings(), const std::vector<int>& frames = {}) {
  v1::SubmitJobRequest r;
  r.set_version(kProtocolVersion);
  r.set_main_file("scene.dae");
  v1::SceneFile* f = r.add_files();
  f->set_path("scene.dae");
  f->set_content(std::string(100, 'x'));
  *r.mutable_settings() = to_proto(s);
  for (int frame : frames) r.add_frames(frame);
  return r;
}

std::string refused(const v1::SubmitJobRequest& r) {
  return refusal([&] { admit(r); }, kInvalid);
}

TEST(Admit, AStillWeighsItsPixelsSamplesAndSceneBytes) {
  const Admission a = admit(request());
  EXPECT_TRUE(a.frames.empty());
  EXPECT_EQ(a.pixels, int64_t(testing::kPixels));
  EXPECT_EQ(a.samples, testing::kSamples);
  EXPECT_EQ(a.scene_bytes, 9u + kSceneDiskBlock);  // its path, and its 100 bytes as a disk block
  EXPECT_EQ(a.settings.spp, 10);
}

TEST(Admit, ASequenceWeighsEveryFrame) {
  const Admission a = admit(request(small_settings(), {4, 2, 9}));
  EXPECT_EQ(a.frames, (std::vector<int>{4, 2, 9}));  // in the order given
  EXPECT_EQ(a.pixels, int64_t(testing::kPixels));    // of one frame
  EXPECT_EQ(a.samples, 3 * testing::kSamples);
}

TEST(Admit, AnotherProtocolVersionIsRefusedNamingBoth) {
  v1::SubmitJobRequest r = request();
  r.set_version(kProtocolVersion - 1);
  const std::string why = refused(r);
  EXPECT_TRUE(has(why, "protocol version " + std::to_string(kProtocolVersion - 1) + " not supported")) << why;
  EXPECT_TRUE(has(why, "speaks " + std::to_string(kProtocolVersion))) << why;
}

TEST(Admit, SettingsOutOfRangeAreRefusedNamingTheSetting) {
  RenderSettings s = small_settings();
  s.spp = 0;
  std::string why = refused(request(s));
  EXPECT_TRUE(has(why, "-s:")) << why;
  s = small_settings();
  s.tile_size = RenderSettings::kMaxTileSize + 1;
  why = refused(request(s));
  EXPECT_TRUE(has(why, "--tile:")) << why;
}

// A task's result goes in one call: a tile whose sums pass what a result may carry is
// refused at submit, naming the tile size that fits (a worker released such a task, and
// the job failed only once two had rendered it; found by audit).
TEST(Admit, ATileWhoseResultNoCallCanCarryIsRefusedNamingOneThatFits) {
  RenderSettings s = small_settings();
  s.camera.width = s.camera.height = 4096;
  s.tile_size = 4096;  // 604 MiB of sums
  std::string why = refused(request(s));
  EXPECT_TRUE(has(why, "--tile 4096: a task's sums take up to 576 MiB, over the 384 MiB a result may carry")) << why;
  EXPECT_TRUE(has(why, "give --tile 3344 or less")) << why;
  s.tile_size = 3344;
  EXPECT_NO_THROW(admit(request(s)));
  s.camera.width = 64;  // a tile no larger than the frame's window counts what it covers
  s.tile_size = 4096;
  EXPECT_NO_THROW(admit(request(s)));
}

TEST(Admit, AJobNameIsAtMost256Bytes) {
  v1::SubmitJobRequest r = request();
  r.set_name(std::string(kMaxJobNameBytes, 'n'));
  EXPECT_NO_THROW(admit(r));
  r.set_name(std::string(kMaxJobNameBytes + 1, 'n'));
  EXPECT_EQ(refused(r), "a job name of 257 bytes; at most 256");
}

TEST(Admit, AFrameGivenTwiceIsRefused) {
  const std::string why = refused(request(small_settings(), {1, 2, 1}));
  EXPECT_EQ(why, "frame 1 given twice");
}

TEST(Admit, AFrameOutOfRangeIsRefusedAndTheRangesEndsAreAdmitted) {
  const int max = RenderSettings::kMaxFrame;
  std::string why = refused(request(small_settings(), {0, max + 1}));
  EXPECT_TRUE(has(why, "frame " + std::to_string(max + 1) + " out of range")) << why;
  why = refused(request(small_settings(), {-max - 1}));
  EXPECT_TRUE(has(why, "frame " + std::to_string(-max - 1) + " out of range")) << why;
  EXPECT_EQ(admit(request(small_settings(), {-max, max})).frames.size(), 2u);
}

TEST(Admit, ASequencesSettingsCarryNoFrameNumberThoughAStillsMay) {
  RenderSettings s = small_settings();
  s.frame = 4;
  const std::string why = refused(request(s, {1, 2}));
  EXPECT_TRUE(has(why, "a sequence's settings have no frame number")) << why;
  EXPECT_EQ(admit(request(s)).settings.frame, 4);  // a still of frame 4
}

TEST(Admit, TooManyFramesAreRefusedBeforeAnyIsLookedAt) {
  // kMaxFrames + 1 copies of frame 0: the count is refused, not the repeats.
  const std::string why = refused(request(small_settings(), std::vector<int>(kMaxFrames + 1, 0)));
  EXPECT_EQ(why, std::to_string(kMaxFrames + 1) + " frames; at most " + std::to_string(kMaxFrames) + " in one job");
  std::vector<int> most(kMaxFrames);
  for (size_t i = 0; i < most.size(); ++i) most[i] = int(i);
  EXPECT_EQ(admit(request(small_settings(), most)).samples, kMaxFrames * testing::kSamples);
}
// The most pixels, samples and frames together are more samples than 64 bits count: the
// total stops at the maximum, and the queued-samples limit refuses it (it wrapped to a
// small number before, and passed).
TEST(Admit, SamplesPastSixtyFourBitsSaturateAndAreRefused) {
  RenderSettings s = small_settings();
  s.camera.width = 16384;
  s.camera.height = 8192;
  s.tile_size = 64;
  s.spp = RenderSettings::kMaxSpp;
  std::vector<int> frames(kMaxFrames);
  for (size_t i = 0; i < frames.size(); ++i) frames[i] = int(i);
  Admission a = admit(request(s, frames));
  EXPECT_EQ(a.samples, std::numeric_limits<uint64_t>::max());
  Load load;
  CoordinatorOptions o;
  o.max_live_pixels = int64_t(1) << 27;
  EXPECT_TRUE(has(over_limit(a, load, o, "ann"), "(--max-queued-samples-per-client)"));
  a.samples = 1000;  // and a sum of queued samples near the top does not wrap either
  load.client_samples_remaining = std::numeric_limits<uint64_t>::max() - 10;
  EXPECT_TRUE(has(over_limit(a, load, o, "ann"), "(--max-queued-samples-per-client)"));
}

// ---- over_limit: each limit refuses one past it, with the numbers, and fits exactly at it.

struct Limit {
  const char* name;
  // Sets the options' limit and the load so that the job fits exactly when `past` is 0
  // and passes the limit by `past`.
  void (*set)(Admission& a, Load& load, CoordinatorOptions& o, uint64_t past);
  std::vector<std::string> said;  // in the message one past the limit
};

const Limit kLimits[] = {
    {"SceneBytes",
     [](Admission& a, Load& l, CoordinatorOptions& o, uint64_t past) {
       o.max_scene_bytes_per_client = 100;
       l.client_scene_bytes = 90;
       a.scene_bytes = 10 + past;
     },
     {"client 'ann''s live jobs hold 90 scene bytes", "this job's 11 ", "limit of 100 ",
      "(--max-scene-bytes-per-client)"}},
    {"QueuedSamples",
     [](Admission& a, Load& l, CoordinatorOptions& o, uint64_t past) {
       o.max_queued_samples_per_client = 5000;
       l.client_samples_remaining = 4000;
       a.samples = 1000 + past;
     },
     {"client 'ann' has 4000 samples queued", "this job's 1001 ", "limit of 5000 ",
      "(--max-queued-samples-per-client)"}},
    {"LiveJobs",
     [](Admission&, Load& l, CoordinatorOptions& o, uint64_t past) {
       o.max_jobs_per_client = 3;
       l.client_jobs = 2 + past;  // this job makes the third
     },
     {"client 'ann' has 3 live jobs, the most allowed (--max-jobs-per-client)"}},
    {"LivePixels",
     [](Admission& a, Load& l, CoordinatorOptions& o, uint64_t past) {
       o.max_live_pixels = 1000;
       l.live_pixels = 900;
       a.pixels = int64_t(100 + past);
     },
     {"live frames hold 900 pixels", "this job's 101 ", "limit of 1000 ", "(--max-live-pixels); try again later"}},
    {"AFrameNoMachineHere",  // bigger than the limit alone: never, however empty the farm
     [](Admission& a, Load&, CoordinatorOptions& o, uint64_t past) {
       o.max_live_pixels = int64_t(1) << 20;
       a.pixels = (int64_t(1) << 20) + int64_t(past);
     },
     {"a frame of 1048577 pixels needs 40 MiB of film (40 bytes a pixel)", "at most 1048576 live pixels (40 MiB",
      "--max-live-pixels): render it in parts (-p)"}},
};

// An 8K frame's film is 1.33 GB: a 4 GB machine takes it, a 2 GB one refuses it at submit.
TEST(LivePixelDefault, HalfTheMachinesMemoryAtMost) {
  EXPECT_EQ(live_pixel_default(uint64_t(64) << 30), int64_t(1) << 27);
  EXPECT_GT(live_pixel_default(uint64_t(4) << 30), 7680 * 4320);
  EXPECT_LT(live_pixel_default(uint64_t(2) << 30), 7680 * 4320);
}

class OverLimit : public ::testing::TestWithParam<Limit> {
 protected:
  std::string over(uint64_t past, const std::string& owner = "ann") const {
    Admission a;
    a.pixels = 1;
    a.samples = 1;
    a.scene_bytes = 1;
    Load load;
    CoordinatorOptions o;
    GetParam().set(a, load, o, past);
    return over_limit(a, load, o, owner);
  }
};

TEST_P(OverLimit, FitsExactlyAtTheLimit) { EXPECT_EQ(over(0), ""); }

TEST_P(OverLimit, OnePastItIsRefusedWithTheNumbers) {
  const std::string why = over(1);
  for (const std::string& part : GetParam().said) EXPECT_TRUE(has(why, part)) << why << "\nlacks: " << part;
}

TEST_P(OverLimit, WithoutTokensTheClientIsThisCoordinator) {
  const std::string why = over(1, "");
  EXPECT_FALSE(has(why, "client ''")) << why;
  if (has(GetParam().said[0], "client 'ann'")) {
    EXPECT_TRUE(has(why, "this coordinator")) << why;
  }
}

INSTANTIATE_TEST_SUITE_P(EachLimit, OverLimit, ::testing::ValuesIn(kLimits),
                         [](const ::testing::TestParamInfo<Limit>& info) { return std::string(info.param.name); });

TEST(OverLimitOrder, TheFirstLimitPassedIsTheOneSaid) {
  // Every limit passed at once: scene bytes are checked first (they are the client's own).
  Admission a;
  Load load;
  CoordinatorOptions o;
  for (const Limit& l : kLimits) l.set(a, load, o, 1);
  EXPECT_TRUE(has(over_limit(a, load, o, "ann"), "scene bytes"));
}

}  // namespace
}  // namespace tessera
