// JobTable: jobs and sequences by id, a frame's job by its number, and Load, the one count
// of what live work weighs (admission, starting frames and autoscalers read it).
#include "server/job_table.h"

#include <gtest/gtest.h>

#include <set>

#include "server/job_status.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::has;
using testing::kPixels;
using testing::kSamples;
using testing::kTiles;
using testing::refusal;
using Code = RequestError::Code;

class JobTableTest : public testing::PartsTest {};

TEST_F(JobTableTest, NewIdsAreSixteenHexDigitsAndNeverOneInUse) {
  const std::string taken = add_still()->id();
  std::set<std::string> seen{taken};
  for (int i = 0; i < 1000; ++i) {
    const std::string id = jobs.new_id();
    ASSERT_EQ(id.size(), 16u) << id;
    EXPECT_EQ(id.find_first_not_of("0123456789abcdef"), std::string::npos) << id;
    EXPECT_TRUE(seen.insert(id).second) << id << " repeats";  // 64 random bits: a repeat is a bug
  }
}

TEST_F(JobTableTest, SubmissionOrderGoesOnPastRestoredJobs) {
  const uint64_t first = jobs.next_seq();
  EXPECT_EQ(jobs.next_seq(), first + 1);
  jobs.saw_seq(first + 40);
  EXPECT_EQ(jobs.next_seq(), first + 41);
  jobs.saw_seq(1);  // an older one never goes back
  EXPECT_EQ(jobs.next_seq(), first + 42);
}

TEST_F(JobTableTest, AnUnknownIdIsNotFound) {
  EXPECT_EQ(jobs.find_job("nope"), nullptr);
  EXPECT_EQ(jobs.find_sequence("nope"), nullptr);
  EXPECT_EQ(jobs.shared("nope"), nullptr);
  EXPECT_EQ(refusal([&] { jobs.job("nope"); }, Code::kNotFound), "no job 'nope'");
  refusal([&] { jobs.frame_job("nope", 1); }, Code::kNotFound);
}

TEST_F(JobTableTest, ASequencesFrameMustBeNamed) {
  const Sequence& s = add_sequence({5, 6, 7});
  const std::string why = refusal([&] { jobs.frame_job(s.id(), std::nullopt); }, Code::kInvalidArgument);
  EXPECT_TRUE(has(why, "is a sequence of 3 frames: name one")) << why;
}

TEST_F(JobTableTest, AFrameTheSequenceDoesNotHaveIsNotFound) {
  const Sequence& s = add_sequence({5, 6, 7});
  const std::string why = refusal([&] { jobs.frame_job(s.id(), 8); }, Code::kNotFound);
  EXPECT_EQ(why, "job " + s.id() + " has no frame 8");
}

TEST_F(JobTableTest, AFrameNotStartedIsAFailedPreconditionSayingWhy) {
  Sequence& s = add_sequence({5, 6, 7});
  std::string why = refusal([&] { jobs.frame_job(s.id(), 6); }, Code::kFailedPrecondition);
  EXPECT_EQ(why, "job " + s.id() + ": frame 6 has not started yet");
  lifecycle.cancel(s.id(), "", true, now, fx);
  why = refusal([&] { jobs.frame_job(s.id(), 6); }, Code::kFailedPrecondition);
  EXPECT_EQ(why, "job " + s.id() + ": frame 6 was never rendered (the job ended first)");
}

TEST_F(JobTableTest, AStartedFrameIsFoundByItsNumber) {
  Sequence& s = add_sequence({5, 6, 7});
  Job& five = start_frame(s);
  EXPECT_EQ(&jobs.frame_job(s.id(), 5), &five);
  EXPECT_EQ(&jobs.job(s.frame_job_id(0)), &five);  // and by its own id
}

TEST_F(JobTableTest, AStillAnswersForItsOwnFrameNumberOrForNone) {
  const std::string plain = add_still()->id();
  EXPECT_EQ(&jobs.frame_job(plain, std::nullopt), jobs.find_job(plain));
  EXPECT_EQ(refusal([&] { jobs.frame_job(plain, 3); }, Code::kInvalidArgument), "job " + plain + " has no frame 3");
  RenderSettings s = testing::small_settings();
  s.frame = 3;
  const std::string three = add_still(s)->id();
  EXPECT_EQ(&jobs.frame_job(three, 3), jobs.find_job(three));
  EXPECT_EQ(&jobs.frame_job(three, std::nullopt), jobs.find_job(three));
  refusal([&] { jobs.frame_job(three, 4); }, Code::kInvalidArgument);
}

// ---- Load ----

TEST_F(JobTableTest, AStillWeighsItsFilmReadyTasksAndSamplesLeft) {
  Job& job = *add_still(testing::small_settings(), "ann");
  Load l = jobs.load("ann");
  EXPECT_EQ(l.live_pixels, int64_t(kPixels));
  EXPECT_EQ(l.tasks_ready, kTiles);
  EXPECT_EQ(l.samples_remaining, kSamples);
  EXPECT_EQ(l.client_jobs, 1u);
  EXPECT_EQ(l.client_scene_bytes, 1000u);
  EXPECT_EQ(l.client_samples_remaining, kSamples);
  // Tile 0's first pass merged: 256 pixels x 4 samples fewer left, its second pass ready.
  ASSERT_EQ(job.plan.merge(0, 0, testing::plausible_sums(job.plan, 0, 0)), FramePlan::Merge::kMerged);
  l = jobs.load("ann");
  EXPECT_EQ(l.samples_remaining, kSamples - testing::kFirstPassSamples);
  EXPECT_EQ(l.client_samples_remaining, kSamples - testing::kFirstPassSamples);
  EXPECT_EQ(l.tasks_ready, kTiles);
  lifecycle.end(job, v1::JobStatus::CANCELLED, now, fx);  // an ended job weighs nothing
  l = jobs.load("ann");
  EXPECT_EQ(l.live_pixels, 0);
  EXPECT_EQ(l.tasks_ready + l.samples_remaining + l.client_jobs + l.client_scene_bytes, 0u);
}

TEST_F(JobTableTest, AnotherOwnersJobsCountInTheTotalOnly) {
  add_still(testing::small_settings(), "ann");
  add_still(testing::small_settings(), "bob");
  const Load l = jobs.load("ann");
  EXPECT_EQ(l.live_pixels, 2 * int64_t(kPixels));
  EXPECT_EQ(l.tasks_ready, 2 * kTiles);
  EXPECT_EQ(l.samples_remaining, 2 * kSamples);
  EXPECT_EQ(l.client_jobs, 1u);
  EXPECT_EQ(l.client_scene_bytes, 1000u);
  EXPECT_EQ(l.client_samples_remaining, kSamples);
}

TEST_F(JobTableTest, ASequenceIsOneJobWithOneSceneAndEveryFramesSamples) {
  Sequence& s = add_sequence({0, 1, 2}, testing::small_settings(), "ann");
  Load l = jobs.load("ann");
  EXPECT_EQ(l.live_pixels, 0);       // no frame's film yet
  EXPECT_EQ(l.tasks_ready, kTiles);  // the next frame's first pass
  EXPECT_EQ(l.samples_remaining, 3 * kSamples);
  EXPECT_EQ(l.client_jobs, 1u);
  EXPECT_EQ(l.client_scene_bytes, 1000u);
  EXPECT_EQ(l.client_samples_remaining, 3 * kSamples);
  start_frame(s);  // its frames are jobs too, but count in their sequence
  l = jobs.load("ann");
  EXPECT_EQ(l.live_pixels, int64_t(kPixels));
  EXPECT_EQ(l.tasks_ready, 2 * kTiles);  // frame 0's, and frame 1's first pass
  EXPECT_EQ(l.samples_remaining, 3 * kSamples);
  EXPECT_EQ(l.client_jobs, 1u);
  EXPECT_EQ(l.client_scene_bytes, 1000u);
  EXPECT_EQ(l.client_samples_remaining, 3 * kSamples);
}

TEST_F(JobTableTest, ASequenceWithAGapInItsStartedFramesCountsItsUnstartedSamplesOnce) {
  // As a restart leaves it (Recovery): frames 0 and 2 have checkpoints, frame 1 had not
  // started. One frame is unstarted, not the two past `next` (the bug this guards).
  Sequence& s = add_sequence({0, 1, 2}, testing::small_settings(), "ann");
  restore_frames(s, {0, 2});
  ASSERT_EQ(s.next, 1u);
  const Load l = jobs.load("ann");
  EXPECT_EQ(l.samples_remaining, 3 * kSamples);
  EXPECT_EQ(l.client_samples_remaining, 3 * kSamples);
  EXPECT_EQ(l.live_pixels, 2 * int64_t(kPixels));
  EXPECT_EQ(l.tasks_ready, 3 * kTiles);  // two frames' first passes, and the next one's
  EXPECT_EQ(l.client_jobs, 1u);
}

TEST_F(JobTableTest, AChangeIsTheOwnersOrAnAdminsAndAFrameChangesWithItsSequence) {
  std::shared_ptr<Job> job = add_still(testing::small_settings(), "ann");
  Sequence& s = add_sequence({1, 2}, testing::small_settings(), "ann");
  Job& frame = start_frame(s);
  EXPECT_EQ(jobs.check_change(job->id(), "ann", false, "delete"), "ann");
  EXPECT_NE(refusal([&] { jobs.check_change(job->id(), "bob", false, "delete"); }, Code::kPermissionDenied)
                .find("a client may delete only its own jobs"),
            std::string::npos);
  EXPECT_EQ(jobs.check_change(s.id(), "bob", true, "delete"), "ann");  // an admin
  EXPECT_NE(refusal([&] { jobs.check_change(frame.id(), "ann", false, "requeue"); }, Code::kFailedPrecondition)
                .find("requeue the sequence"),
            std::string::npos);
  refusal([&] { jobs.check_change("nope", "", true, "delete"); }, Code::kNotFound);
}

// Issue 22: a long sequence holds only its live frames. A DONE frame whose image and final
// checkpoint are on disk leaves memory; its sequence still answers for it.
TEST_F(JobTableTest, ADoneFrameWholeOnDiskLeavesMemoryAndItsSequenceAnswersForIt) {
  Sequence& s = add_sequence({4, 5, 6});
  Job& first = start_frame(s);
  testing::merge_passes(first.plan, uint32_t(first.plan.passes().size()));
  first.merged_by[77] = {0, 1, 0};
  EXPECT_FALSE(jobs.let_go(first));  // live
  lifecycle.finish_if_done(first, now, fx);
  EXPECT_FALSE(jobs.let_go(first));  // its end not recorded, its film still in memory
  first.end_recorded = true;
  first.compact();
  const std::string id = first.id();
  const uint64_t samples = first.plan.samples_merged();
  ASSERT_TRUE(jobs.let_go(first));
  EXPECT_EQ(jobs.find_job(id), nullptr);
  EXPECT_EQ(s.jobs[0], nullptr);
  EXPECT_TRUE(s.frame_left(0));
  EXPECT_TRUE(s.frame_started(0));
  EXPECT_EQ(s.left_merged_by.at(77), 2u);  // tiles, once each
  EXPECT_EQ(s.samples_merged(), samples);
  EXPECT_EQ(SequenceScheduler::next_unstarted(s), 1u);
  // Named by its own id or by its sequence's and number; other frames are not.
  ASSERT_TRUE(jobs.left_frame(id));
  EXPECT_EQ(jobs.left_frame(id)->index, 0u);
  EXPECT_EQ(jobs.left_frame(s.id(), 4)->id(), id);
  EXPECT_FALSE(jobs.left_frame(s.id(), 5));
  EXPECT_FALSE(jobs.left_frame(s.id() + "-f5"));
  EXPECT_FALSE(jobs.left_frame(s.id() + "-fx"));
  EXPECT_TRUE(jobs.names(id));  // its folder is still its sequence's
  const v1::JobStatus st = job_status(jobs, leases, s.id(), false, now);
  EXPECT_EQ(st.frames(0).state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.frames(0).job_id(), id);
  EXPECT_EQ(st.frames(0).samples_done(), samples);
  EXPECT_EQ(st.frames_done(), 1u);
  const v1::JobStatus frame = job_status(jobs, leases, id, true, now);
  EXPECT_EQ(frame.state(), v1::JobStatus::DONE);
  EXPECT_EQ(frame.samples_done(), samples);
  EXPECT_EQ(frame.sequence(), s.id());
  EXPECT_EQ(frame.settings().frame(), 4);
  EXPECT_TRUE(job_progress(jobs, id).ended);
}

}  // namespace
}  // namespace tessera
