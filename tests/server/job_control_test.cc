// JobControl (server/job_control.h): priority, requeue and delete under the coordinator's
// lock, with no disk: the states they leave, what they refuse, and the steps' hand-offs.
#include "server/job_control.h"

#include <gtest/gtest.h>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::merge_passes;
using testing::refusal;
using testing::small_settings;

class JobControlTest : public testing::PartsTest {
 protected:
  JobControl control{jobs, lifecycle, snapshotter, counters};

  // An ended job as the coordinator has it once its end is on disk.
  std::shared_ptr<Job> ended_still(Job::State state, uint32_t passes = 1) {
    std::shared_ptr<Job> job = add_still();
    merge_passes(job->plan, passes);
    lifecycle.end(*job, state, now, fx);
    job->end_recorded = true;
    return job;
  }
  // The plans a requeue reads back from disk (load_requeue): here through a checkpoint in memory.
  void load(JobControl::Requeue& q) {
    MemoryJobStore store;
    for (const std::shared_ptr<Job>& old : q.ended) {
      auto fresh = std::make_shared<Job>(old->meta, old->plan.settings());
      fresh->sequence = old->sequence;
      fresh->frame_index = old->frame_index;
      write_checkpoint(store, old->id(), old->plan, 2.5);
      const std::optional<double> elapsed = store.read_checkpoint(old->id(), fresh->plan);
      q.fresh.push_back(fresh);
      q.elapsed.push_back(elapsed.value_or(-1));
      q.checkpointed.push_back(true);
    }
  }
};

TEST_F(JobControlTest, APriorityReachesASequencesFramesAndTheDispatchOrder) {
  Sequence& s = add_sequence({1, 2});
  Job& frame = start_frame(s);
  control.set_priority(s.id(), 7, fx);
  EXPECT_EQ(s.meta.priority, 7);
  EXPECT_EQ(frame.meta.priority, 7);
  EXPECT_TRUE(fx.changed);
  std::shared_ptr<Job> still = add_still();
  control.set_priority(still->id(), -3, fx);
  EXPECT_EQ(still->meta.priority, -3);
}

TEST_F(JobControlTest, ADeleteEndsALiveJobWithoutALastImageAndWaitsForItsWriter) {
  std::shared_ptr<Job> job = add_still();
  const uint64_t w = add_worker();
  const uint64_t task = lease_next(*job, w);
  ASSERT_TRUE(snapshotter.request(*job, true, true));  // a writer at work
  JobControl::Removal r = control.begin_delete(job->id(), "", true, now, fx);
  EXPECT_EQ(job->state(), v1::JobStatus::CANCELLED);
  EXPECT_TRUE(job->removed);
  EXPECT_EQ(leases.live(task), nullptr);
  EXPECT_TRUE(fx.writes.empty());  // no last image of a job being deleted
  EXPECT_FALSE(snapshotter.request(*job, true, true));
  EXPECT_FALSE(JobControl::quiet(r));
  EXPECT_FALSE(snapshotter.next(*job, now).image);  // the writer stops
  EXPECT_TRUE(JobControl::quiet(r));
  EXPECT_TRUE(JobControl::holds_scene(r));  // its end was never recorded: its use of the scene
  refusal([&] { control.begin_delete(job->id(), "", true, now, fx); }, RequestError::Code::kFailedPrecondition);
  control.removed(r, fx);
  EXPECT_EQ(jobs.find_job(job->id()), nullptr);
  EXPECT_EQ(jobs.listed(), 0u);
  EXPECT_EQ(counters.jobs_deleted, 1u);
}

TEST_F(JobControlTest, ADeleteThatCouldNotRecordLeavesTheJobEndedAsUsual) {
  std::shared_ptr<Job> job = add_still();
  merge_passes(job->plan, 1);
  JobControl::Removal r = control.begin_delete(job->id(), "", true, now, fx);
  fx = Effects();
  control.delete_failed(r, now, fx);
  EXPECT_FALSE(job->removed);
  EXPECT_EQ(jobs.find_job(job->id()), job.get());
  ASSERT_EQ(fx.writes.size(), 1u);  // its last image and checkpoint, then its end recorded
  EXPECT_EQ(fx.writes[0], job);
}

TEST_F(JobControlTest, ADeletedSequenceTakesItsFramesAndNeverRecordsItsEnd) {
  Sequence& s = add_sequence({4, 5, 6});
  start_frame(s);
  JobControl::Removal r = control.begin_delete(s.id(), "", true, now, fx);
  EXPECT_EQ(r.job_ids, (std::vector<std::string>{s.frame_job_id(0), s.frame_job_id(1), s.frame_job_id(2)}));
  EXPECT_EQ(r.jobs.size(), 1u);
  EXPECT_EQ(s.state(), v1::JobStatus::CANCELLED);
  EXPECT_FALSE(lifecycle.sequence_end_due(s.id()));  // being deleted: its end is not recorded
  EXPECT_TRUE(JobControl::holds_scene(r));
  const std::string id = s.id(), frame = s.frame_job_id(0);
  control.removed(r, fx);
  EXPECT_EQ(jobs.find_sequence(id), nullptr);
  EXPECT_EQ(jobs.find_job(frame), nullptr);
  EXPECT_FALSE(jobs.names(frame));
}

TEST_F(JobControlTest, OnlyADurablyEndedFailedOrCancelledJobIsRequeued) {
  std::shared_ptr<Job> live = add_still();
  refusal([&] { control.begin_requeue(live->id(), "", true); }, RequestError::Code::kFailedPrecondition);
  std::shared_ptr<Job> done = ended_still(v1::JobStatus::DONE);
  EXPECT_NE(refusal([&] { control.begin_requeue(done->id(), "", true); }, RequestError::Code::kFailedPrecondition)
                .find("DONE"),
            std::string::npos);
  std::shared_ptr<Job> recording = ended_still(v1::JobStatus::CANCELLED);
  recording->end_recorded = false;
  refusal([&] { control.begin_requeue(recording->id(), "", true); }, RequestError::Code::kFailedPrecondition);
  std::shared_ptr<Job> failed = ended_still(v1::JobStatus::FAILED);
  JobControl::Requeue q = control.begin_requeue(failed->id(), "", true);
  refusal([&] { control.begin_requeue(failed->id(), "", true); }, RequestError::Code::kFailedPrecondition);
  refusal([&] { control.begin_delete(failed->id(), "", true, now, fx); }, RequestError::Code::kFailedPrecondition);
  control.requeue_failed(q);
  EXPECT_NO_THROW(control.begin_requeue(failed->id(), "", true));
}

TEST_F(JobControlTest, ARequeuedJobIsLiveAgainWithItsPlanAndNoError) {
  std::shared_ptr<Job> old = ended_still(v1::JobStatus::FAILED);
  old->error = "tasks failed on 2 workers";
  JobControl::Requeue q = control.begin_requeue(old->id(), "", true);
  load(q);
  control.finish_requeue(q, now, fx);
  Job* j = jobs.find_job(old->id());
  ASSERT_NE(j, nullptr);
  EXPECT_NE(j, old.get());
  EXPECT_EQ(j->state(), v1::JobStatus::RUNNING);
  EXPECT_TRUE(j->error.empty());
  EXPECT_FALSE(j->end_recorded);
  EXPECT_EQ(j->plan.merges(), old->plan.merges());
  EXPECT_DOUBLE_EQ(j->started, now - 2.5);
  EXPECT_EQ(counters.jobs_requeued, 1u);
  EXPECT_GT(jobs.load().tasks_ready, 0u);
}

TEST_F(JobControlTest, ARequeuedSequenceTakesUpItsUnfinishedFramesAndStartsTheRest) {
  Sequence& s = add_sequence({1, 2, 3});
  Job& first = start_frame(s);
  merge_passes(first.plan, uint32_t(first.plan.passes().size()));
  lifecycle.finish_if_done(first, now, fx);
  Job& second = start_frame(s);
  merge_passes(second.plan, 1);
  lifecycle.cancel(s.id(), "", true, now, fx);
  s.end_recorded = true;
  JobControl::Requeue q = control.begin_requeue(s.id(), "", true);
  ASSERT_EQ(q.ended.size(), 1u);  // the DONE frame stays as it is
  EXPECT_EQ(q.ended[0]->id(), second.id());
  load(q);
  control.finish_requeue(q, now, fx);
  EXPECT_TRUE(s.live());
  EXPECT_EQ(s.live_frames, 1u);
  EXPECT_EQ(s.jobs[1]->state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(s.jobs[0]->state(), v1::JobStatus::DONE);
  EXPECT_TRUE(SequenceScheduler::may_start(s));  // frame 3 is yet to start
}

}  // namespace
}  // namespace tessera
