// What clients see of jobs: a still's or a sequence's status, with the workers leasing its
// tasks, and the list of every job in submission order, frames inside their sequences.
#include "server/job_status.h"

#include <gtest/gtest.h>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::kFirstPassSamples;
using testing::kSamples;
using testing::kTiles;
using testing::refusal;

class JobStatusTest : public testing::PartsTest {
 protected:
  uint64_t a = add_worker(), b = add_worker();
  v1::JobStatus status(const std::string& id, bool with_tiles = false) const {
    return job_status(jobs, leases, id, with_tiles, now);
  }
};

TEST_F(JobStatusTest, AStillsStatusSaysHowFarItIsAndWhoIsOnIt) {
  const std::shared_ptr<Job> job = add_still(testing::small_settings(), "ann", 3);
  ASSERT_TRUE(submit(result(lease_next(*job, a))).accepted());
  lease_next(*job, a);
  lease_next(*job, b);
  now += 10;
  const v1::JobStatus st = status(job->id());
  EXPECT_EQ(st.id(), job->id());
  EXPECT_EQ(st.name(), job->meta.name);
  EXPECT_EQ(st.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.owner(), "ann");
  EXPECT_EQ(st.priority(), 3);
  EXPECT_EQ(st.samples_done(), kFirstPassSamples);
  EXPECT_EQ(st.samples_total(), kSamples);
  EXPECT_EQ(st.tiles_done(), 0u);
  EXPECT_EQ(st.tiles_total(), kTiles);
  EXPECT_EQ(st.passes_total(), testing::kPasses);
  EXPECT_EQ(st.active_workers(), 2u);
  EXPECT_EQ(st.elapsed_seconds(), 10);
  const double f = job->plan.fraction_done();
  EXPECT_EQ(st.eta_seconds(), 10 * (1 - f) / f);  // at the rate so far
  EXPECT_EQ(st.settings().spp(), 10u);
  EXPECT_EQ(st.sequence(), "");
  EXPECT_EQ(st.frames_total(), 0u);
  EXPECT_EQ(st.tiles_size(), 0);
}

TEST_F(JobStatusTest, WithTilesEachTileSaysItsPasses) {
  const std::shared_ptr<Job> job = add_still();
  ASSERT_TRUE(submit(result(lease_next(*job, a))).accepted());
  const v1::JobStatus st = status(job->id(), true);
  ASSERT_EQ(st.tiles_size(), int(kTiles));
  EXPECT_EQ(st.tiles(0).passes_done(), 1u);
  EXPECT_EQ(st.tiles(0).samples(), 4u);
  EXPECT_EQ(from_proto(st.tiles(0).rect()), job->plan.tiles()[0]);
  EXPECT_EQ(st.tiles(1).passes_done(), 0u);
}

TEST_F(JobStatusTest, AStillsErrorSaysWhyItsImageIsMissing) {
  const std::shared_ptr<Job> job = add_still();
  job->image_error = "disk full";
  job->checkpoint_error = "read-only";
  EXPECT_EQ(status(job->id()).error(), "image not written: disk full; checkpoint not written: read-only");
}

// One worker on two frames of a sequence is one worker (the sum per frame counted it twice).
TEST_F(JobStatusTest, AWorkerOnTwoFramesOfASequenceCountsOnce) {
  Sequence& s = add_sequence({1, 2}, testing::small_settings(), "ann");
  Job& one = start_frame(s);
  Job& two = start_frame(s);
  lease_next(one, a);
  lease_next(two, a);
  EXPECT_EQ(status(s.id()).active_workers(), 1u);
  lease_next(two, b);
  EXPECT_EQ(status(s.id()).active_workers(), 2u);
}

TEST_F(JobStatusTest, ASequencesStatusHasEveryFrame) {
  Sequence& s = add_sequence({3, 4, 5}, testing::small_settings(), "ann");
  Job& three = start_frame(s);
  lease_next(three, a);
  const v1::JobStatus st = status(s.id());
  EXPECT_EQ(st.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.frames_total(), 3u);
  EXPECT_EQ(st.frames_done(), 0u);
  EXPECT_EQ(st.samples_total(), 3 * kSamples);
  EXPECT_EQ(st.tiles_total(), 3 * kTiles);
  EXPECT_EQ(st.active_workers(), 1u);
  ASSERT_EQ(st.frames_size(), 3);
  EXPECT_EQ(st.frames(0).frame(), 3);
  EXPECT_EQ(st.frames(0).state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.frames(0).job_id(), three.id());
  EXPECT_EQ(st.frames(1).frame(), 4);
  EXPECT_EQ(st.frames(1).state(), v1::JobStatus::QUEUED);  // not started
  EXPECT_EQ(st.frames(1).job_id(), "");
  EXPECT_EQ(st.frames(1).samples_total(), kSamples);
  const v1::JobStatus frame = status(three.id());  // the frame's own job
  EXPECT_EQ(frame.sequence(), s.id());
}

TEST_F(JobStatusTest, FramesThatNeverStartedAreCancelledWithTheirSequence) {
  Sequence& s = add_sequence({3, 4});
  start_frame(s);
  lifecycle.cancel(s.id(), "", true, now, fx);
  // Clients are told of an end once it is durable: before, the sequence and its frame read
  // RUNNING; the coordinator records both ends after the lock (SnapshotWriter, JobLifecycle).
  EXPECT_EQ(status(s.id()).state(), v1::JobStatus::RUNNING);
  s.end_recorded = true;
  for (const auto& j : s.jobs)
    if (j) j->end_recorded = true;
  const v1::JobStatus st = status(s.id());
  EXPECT_EQ(st.state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(st.frames(0).state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(st.frames(1).state(), v1::JobStatus::CANCELLED);
}

// A list counts a sequence's frames but does not list them (found by review: ten sequences
// of 100,000 frames made /api/status 122 MB, polled every second by the live page, and a
// ListJobs page could pass the message limit); one job's status lists them.
TEST_F(JobStatusTest, TheListIsInSubmissionOrderWithFramesCountedInsideTheirSequence) {
  // Ids are random: the tables' order by id is not the order of submission.
  const std::string first = add_still()->id();
  Sequence& s = add_sequence({1, 2});
  start_frame(s);
  const std::string last = add_still()->id();
  const std::vector<v1::JobStatus> list = job_list(jobs, leases, now);
  ASSERT_EQ(list.size(), 3u);
  EXPECT_EQ(list[0].id(), first);
  EXPECT_EQ(list[1].id(), s.id());
  EXPECT_EQ(list[1].frames_size(), 0);
  EXPECT_EQ(list[1].frames_total(), 2u);
  EXPECT_EQ(list[2].id(), last);
  EXPECT_EQ(job_status(jobs, leases, s.id(), false, now).frames_size(), 2);
}

TEST(KeepChangedFrames, AWatcherGetsEveryFrameFirstThenOnlyThoseThatChanged) {
  v1::JobStatus s;
  for (int f = 1; f <= 4; ++f) s.add_frames()->set_frame(f);
  std::vector<std::string> sent;
  v1::JobStatus first = s;
  keep_changed_frames(first, sent);
  EXPECT_EQ(first.frames_size(), 4);
  EXPECT_FALSE(first.frames_changed_only());
  v1::JobStatus same = s;  // nothing moved: no frame
  keep_changed_frames(same, sent);
  EXPECT_EQ(same.frames_size(), 0);
  EXPECT_TRUE(same.frames_changed_only());
  s.mutable_frames(2)->set_samples_done(7);
  s.mutable_frames(0)->set_state(v1::JobStatus::DONE);
  v1::JobStatus moved = s;
  keep_changed_frames(moved, sent);
  ASSERT_EQ(moved.frames_size(), 2);
  EXPECT_EQ(moved.frames(0).frame(), 1);
  EXPECT_EQ(moved.frames(1).frame(), 3);
  EXPECT_EQ(moved.frames(1).samples_done(), 7u);
  v1::JobStatus still = s;  // a still has no frames: nothing changes
  still.clear_frames();
  std::vector<std::string> none;
  keep_changed_frames(still, none);
  keep_changed_frames(still, none);
  EXPECT_FALSE(still.frames_changed_only());
}

TEST_F(JobStatusTest, AnUnknownJobIsNotFound) {
  refusal([&] { status("nope"); }, RequestError::Code::kNotFound);
}

}  // namespace
}  // namespace tessera
