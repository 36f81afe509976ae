// JobLifecycle: the one writer of job and sequence states. QUEUED -> RUNNING at the first
// lease, then one end; an end releases what the job held and reports a frame's end to its
// sequence.
#include "server/job_lifecycle.h"

#include <gtest/gtest.h>

#include "core/util/invariant.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::contains;
using testing::has;
using testing::refusal;
using Code = RequestError::Code;
constexpr auto QUEUED = v1::JobStatus::QUEUED, RUNNING = v1::JobStatus::RUNNING, DONE = v1::JobStatus::DONE,
               CANCELLED = v1::JobStatus::CANCELLED, FAILED = v1::JobStatus::FAILED;

class JobLifecycleTest : public testing::PartsTest {
 protected:
  uint64_t a = add_worker(), b = add_worker();
};

TEST_F(JobLifecycleTest, AJobStartsOnlyFromQueued) {
  Job& job = *add_still();
  lifecycle.start(job, now, fx);
  EXPECT_EQ(job.state(), RUNNING);
  EXPECT_EQ(job.started, now);
  lifecycle.start(job, now + 5, fx);  // its first lease started it; later ones do not
  EXPECT_EQ(job.started, now);
  Job& ended = *add_still();
  lifecycle.end(ended, CANCELLED, now, fx);
  lifecycle.start(ended, now, fx);
  EXPECT_EQ(ended.state(), CANCELLED);
  EXPECT_EQ(ended.started, 0);
}

TEST_F(JobLifecycleTest, ASequenceStartsOnlyFromQueued) {
  Sequence& s = add_sequence({1, 2});
  lifecycle.start(s, now, fx);
  lifecycle.start(s, now + 5, fx);
  EXPECT_EQ(s.state(), RUNNING);
  EXPECT_EQ(s.started, now);
}

TEST_F(JobLifecycleTest, AnEndReleasesTheJobsLeasesAndChecks) {
  Job& job = *add_still();
  const uint64_t t1 = lease_next(job, a), t2 = lease_next(job, b);
  Check c;
  c.job = job.id();
  const uint64_t check = checks.add(c);
  job.pending_checks = 1;
  lifecycle.end(job, CANCELLED, now + 2, fx);
  EXPECT_EQ(job.state(), CANCELLED);
  EXPECT_EQ(job.finished_at, now + 2);
  EXPECT_EQ(job.pending_checks, 0u);
  EXPECT_EQ(leases.known(t1), nullptr);
  EXPECT_EQ(leases.known(t2), nullptr);
  EXPECT_EQ(checks.find(check), nullptr);
  EXPECT_EQ(worker(a).leases + worker(b).leases, 0u);
  EXPECT_TRUE(fx.changed);
  EXPECT_TRUE(fx.writes.empty());  // the caller asks for a job's last image
}

TEST_F(JobLifecycleTest, AFramesEndIsMarkedInItsSequence) {
  Sequence& s = add_sequence({1, 2});
  Job& one = start_frame(s);
  start_frame(s);
  ASSERT_EQ(s.live_frames, 2u);
  const uint64_t changes = s.changes;
  lifecycle.end(one, DONE, now, fx);
  EXPECT_EQ(s.live_frames, 1u);
  EXPECT_EQ(s.frames_done, 1u);
  EXPECT_EQ(s.changes, changes + 1);  // watchers of the sequence wake
  EXPECT_TRUE(contains(fx.sequence_ends, s.id()));
  EXPECT_TRUE(s.live());
}

TEST_F(JobLifecycleTest, ASequenceWhoseFramesAllEndDoneEndsDone) {
  Sequence& s = add_sequence({1, 2, 3});
  std::vector<Job*> frames;
  for (int i = 0; i < 3; ++i) frames.push_back(&start_frame(s));
  lifecycle.end(*frames[1], DONE, now, fx);
  lifecycle.end(*frames[0], DONE, now, fx);
  EXPECT_TRUE(s.live());
  EXPECT_EQ(s.frames_done, 2u);
  lifecycle.end(*frames[2], DONE, now + 9, fx);
  EXPECT_EQ(s.state(), DONE);
  EXPECT_EQ(s.finished_at, now + 9);
  EXPECT_EQ(s.frames_done, 3u);
  EXPECT_EQ(s.live_frames, 0u);
}

TEST_F(JobLifecycleTest, ASequenceEndsDoneOnItsCountOfDoneFramesNotByLookingAtThem) {
  // The count decides (O(1) per frame end, for long sequences): frames already counted
  // done are not looked at again.
  Sequence& s = add_sequence({1, 2, 3});
  Job& first = start_frame(s);
  s.frames_done = 2;  // as if two frames had ended DONE
  lifecycle.end(first, DONE, now, fx);
  EXPECT_EQ(s.state(), DONE);
}

TEST_F(JobLifecycleTest, AFailedFrameFailsItsSequenceAndCancelsTheOtherLiveFrames) {
  Sequence& s = add_sequence({4, 5, 6});
  Job& four = start_frame(s);
  Job& five = start_frame(s);
  const std::shared_ptr<Job> five_shared = jobs.shared(five.id());
  four.error = "out of memory";
  lifecycle.end(four, FAILED, now, fx);
  EXPECT_EQ(s.state(), FAILED);
  EXPECT_EQ(s.error, "frame 4: out of memory");
  EXPECT_EQ(five.state(), CANCELLED);
  EXPECT_TRUE(contains(fx.writes, five_shared));  // it keeps what it rendered
  EXPECT_TRUE(five.snaps.image_due && five.snaps.checkpoint_due);
  EXPECT_FALSE(contains(fx.writes, jobs.shared(four.id())));  // the caller's
  EXPECT_EQ(s.prepared, nullptr);
  EXPECT_EQ(s.frames_started, 2u);  // frame 6 never starts
  EXPECT_EQ(sequences.start_next(s, now, fx), nullptr);
}

TEST_F(JobLifecycleTest, AJobFinishesOnlyWhenItsPlanIsDoneAndItsChecksDecided) {
  const std::shared_ptr<Job> job = add_still();
  testing::merge_passes(job->plan, testing::kPasses - 1);
  EXPECT_FALSE(lifecycle.finish_if_done(*job, now, fx));  // a pass left
  testing::merge_passes(job->plan, testing::kPasses);
  job->pending_checks = 1;
  EXPECT_FALSE(lifecycle.finish_if_done(*job, now, fx));  // a check not decided
  EXPECT_TRUE(job->live());
  EXPECT_TRUE(fx.writes.empty());
  job->pending_checks = 0;
  EXPECT_TRUE(lifecycle.finish_if_done(*job, now, fx));
  EXPECT_EQ(job->state(), DONE);
  ASSERT_EQ(fx.writes.size(), 1u);  // its final image and checkpoint, this caller to write them
  EXPECT_EQ(fx.writes[0], job);
  const SnapshotPlan final = snapshotter.next(*job, now);
  EXPECT_TRUE(final.ended);
  EXPECT_EQ(final.state, DONE);
  EXPECT_TRUE(final.image && final.checkpoint);
  EXPECT_EQ(final.merges, job->plan.merges());
  EXPECT_FALSE(lifecycle.finish_if_done(*job, now, fx));  // once
}

TEST_F(JobLifecycleTest, OnlyTheOwnerCancelsUnlessAny) {
  const std::shared_ptr<Job> job = add_still(testing::small_settings(), "ann");
  const std::string why = refusal([&] { lifecycle.cancel(job->id(), "bob", false, now, fx); }, Code::kPermissionDenied);
  EXPECT_TRUE(has(why, "belongs to 'ann'")) << why;
  EXPECT_TRUE(job->live());
  lifecycle.cancel(job->id(), "ann", false, now, fx);
  EXPECT_EQ(job->state(), CANCELLED);
  EXPECT_TRUE(contains(fx.writes, job));  // what was rendered is kept
  const std::shared_ptr<Job> other = add_still(testing::small_settings(), "ann");
  lifecycle.cancel(other->id(), "admin", true, now, fx);
  EXPECT_EQ(other->state(), CANCELLED);
}

TEST_F(JobLifecycleTest, ASequenceIsCancelledWholeNotFrameByFrame) {
  Sequence& s = add_sequence({1, 2}, testing::small_settings(), "ann");
  Job& one = start_frame(s);
  const std::string why =
      refusal([&] { lifecycle.cancel(one.id(), "ann", false, now, fx); }, Code::kFailedPrecondition);
  EXPECT_TRUE(has(why, "cancel the sequence")) << why;
  EXPECT_TRUE(one.live());
  refusal([&] { lifecycle.cancel(s.id(), "bob", false, now, fx); }, Code::kPermissionDenied);
  lifecycle.cancel(s.id(), "ann", false, now, fx);
  EXPECT_EQ(s.state(), CANCELLED);
  EXPECT_EQ(one.state(), CANCELLED);
}

TEST_F(JobLifecycleTest, CancellingAnEndedJobChangesNothing) {
  const std::shared_ptr<Job> job = add_still();
  lifecycle.end(*job, DONE, now, fx);
  fx = {};
  lifecycle.cancel(job->id(), "", true, now + 1, fx);
  EXPECT_EQ(job->state(), DONE);
  EXPECT_EQ(job->finished_at, now);
  EXPECT_TRUE(fx.empty());
  refusal([&] { lifecycle.cancel("nope", "", true, now, fx); }, Code::kNotFound);
}

TEST_F(JobLifecycleTest, TasksFailingOnTwoDistinctWorkersFailTheJob) {
  const std::shared_ptr<Job> job = add_still();
  lifecycle.task_failed(*job, "registration 1", "no GPU", now, fx);
  lifecycle.task_failed(*job, "registration 1", "no GPU", now, fx);  // the same worker's trouble, twice
  EXPECT_TRUE(job->live());
  EXPECT_EQ(counters.tasks_failed, 2u);
  lifecycle.task_failed(*job, "credential w2", std::string(2000, 'e'), now, fx);
  EXPECT_EQ(job->state(), FAILED);
  EXPECT_EQ(job->error, "tasks failed on 2 workers: " + std::string(1024, 'e'));  // the error, cut short
  EXPECT_TRUE(contains(fx.writes, job));
  lifecycle.task_failed(*job, "registration 3", "late", now, fx);  // an ended job counts no more
  EXPECT_EQ(counters.tasks_failed, 3u);
}

TEST_F(JobLifecycleTest, ADoneSequencesEndIsDueOnlyOnceEveryFramesEndIsRecorded) {
  Sequence& s = add_sequence({1, 2});
  Job& one = start_frame(s);
  Job& two = start_frame(s);
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));  // live
  lifecycle.end(one, DONE, now, fx);
  lifecycle.end(two, DONE, now + 4, fx);
  ASSERT_EQ(s.state(), DONE);
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));  // no frame's final checkpoint on disk
  one.end_recorded = true;
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));
  two.end_recorded = true;
  const std::optional<RowEnd> row = lifecycle.sequence_end_due(s.id());
  ASSERT_TRUE(row);
  EXPECT_EQ(row->id, s.id());
  EXPECT_EQ(row->state, DONE);
  EXPECT_EQ(row->elapsed, 4);
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));  // being recorded
  lifecycle.sequence_end_recorded(s.id(), false);    // it failed: due again
  ASSERT_TRUE(lifecycle.sequence_end_due(s.id()));
  lifecycle.sequence_end_recorded(s.id(), true);
  EXPECT_TRUE(s.end_recorded);
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));
}

TEST_F(JobLifecycleTest, ACancelledSequencesEndIsDueAtOnce) {
  Sequence& s = add_sequence({1, 2});
  start_frame(s);
  lifecycle.cancel(s.id(), "", true, now, fx);
  const std::optional<RowEnd> row = lifecycle.sequence_end_due(s.id());
  ASSERT_TRUE(row);
  EXPECT_EQ(row->state, CANCELLED);
}

TEST_F(JobLifecycleTest, EndingTwiceOrIntoALiveStateIsABug) {
  Job& job = *add_still();
  EXPECT_THROW(lifecycle.end(job, RUNNING, now, fx), InvariantError);
  EXPECT_TRUE(job.live());
  lifecycle.end(job, DONE, now, fx);
  EXPECT_THROW(lifecycle.end(job, CANCELLED, now, fx), InvariantError);
  EXPECT_EQ(job.state(), DONE);
  Sequence& s = add_sequence({1});
  EXPECT_THROW(lifecycle.end(s, QUEUED, now, fx), InvariantError);
  lifecycle.end(s, CANCELLED, now, fx);
  EXPECT_THROW(lifecycle.end(s, CANCELLED, now, fx), InvariantError);
  EXPECT_THROW(lifecycle.sequence_end_recorded(s.id(), true), InvariantError);  // not being recorded
}

}  // namespace
}  // namespace tessera
