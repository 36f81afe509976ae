// Dispatcher: which tasks a worker gets. Checks first; then jobs by priority and
// submission, a sequence's next frame after its started ones; at most the worker's share,
// by threads, of the work outstanding; within the request's count and sample limits.
#include "server/dispatcher.h"

#include <gtest/gtest.h>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::has;
using testing::kFirstPassSamples;
using testing::kTiles;
using testing::refusal;
using Code = RequestError::Code;

class DispatcherTest : public testing::PartsTest {
 protected:
  explicit DispatcherTest(CoordinatorOptions o = testing::parts_options()) : PartsTest(std::move(o)) {}
  v1::GetTaskResponse get(uint64_t w, uint32_t max_tasks = Dispatcher::kMaxTasksPerRequest, uint64_t max_samples = 0) {
    return dispatcher.get_task(w, max_tasks, max_samples, now, fx);
  }
  static std::vector<std::string> job_ids(const v1::GetTaskResponse& r) {
    std::vector<std::string> ids;
    for (const v1::Task& t : r.tasks()) ids.push_back(t.job_id());
    return ids;
  }
};

TEST_F(DispatcherTest, ATaskCarriesWhatTheWorkerRendersAndIsLeased) {
  const std::shared_ptr<Job> job = add_still();
  const uint64_t w = add_worker();
  const v1::GetTaskResponse r = get(w, 1);
  ASSERT_EQ(r.tasks_size(), 1);
  const v1::Task& t = r.tasks(0);
  EXPECT_EQ(t.job_id(), job->id());
  EXPECT_EQ(t.scene_hash(), job->meta.scene_hash);
  EXPECT_EQ(from_proto(t.tile()), job->plan.tiles()[0]);
  EXPECT_EQ(t.pass(), 0u);
  EXPECT_EQ(t.sample_begin(), 0u);
  EXPECT_EQ(t.sample_end(), 4u);
  EXPECT_EQ(t.settings().spp(), 10u);
  ASSERT_NE(leases.live(t.task_id()), nullptr);
  EXPECT_EQ(leases.live(t.task_id())->worker, w);
  EXPECT_EQ(job->state(), v1::JobStatus::RUNNING);  // its first lease started it
  EXPECT_EQ(r.retry_after_ms(), 0u);
}

TEST_F(DispatcherTest, HigherPriorityFirstThenSubmissionOrder) {
  const std::string low = add_still(testing::small_settings(), "", 0)->id();
  const std::string high_first = add_still(testing::small_settings(), "", 5)->id();
  const std::string high_second = add_still(testing::small_settings(), "", 5)->id();
  const std::vector<std::string> got = job_ids(get(add_worker()));
  ASSERT_EQ(got.size(), 3 * kTiles);
  for (size_t i = 0; i < got.size(); ++i)
    EXPECT_EQ(got[i], i < kTiles ? high_first : i < 2 * kTiles ? high_second : low) << i;
}

TEST_F(DispatcherTest, AWorkersShareGoesByItsThreads) {
  // 9 tasks outstanding, 4 threads in all: the 1-thread worker may hold ceil(9/4) = 3,
  // the 3-thread one ceil(27/4) = 7 (6 are left for it).
  add_still();
  const uint64_t one = add_worker(1), three = add_worker(3);
  EXPECT_EQ(get(one).tasks_size(), 3);
  EXPECT_EQ(get(one).tasks_size(), 0);  // it holds its share
  EXPECT_EQ(get(three).tasks_size(), 6);
}

// A worker that asks for a huge window gets no more than the bound on one worker's leases
// (CoordinatorOptions::max_leases_per_worker), however much is outstanding.
class DispatcherBoundTest : public DispatcherTest {
 protected:
  static CoordinatorOptions bounded() {
    CoordinatorOptions o = testing::parts_options();
    o.max_leases_per_worker = 5;
    return o;
  }
  DispatcherBoundTest() : DispatcherTest(bounded()) {}
};

TEST_F(DispatcherBoundTest, AWorkerHoldsNoMoreThanTheBoundOnOneWorkersLeases) {
  add_still();
  add_still();
  const uint64_t w = add_worker(64);
  EXPECT_EQ(get(w).tasks_size(), 5);
  EXPECT_EQ(get(w).tasks_size(), 0);  // it holds its bound
  const uint64_t other = add_worker(64);
  EXPECT_EQ(get(other).tasks_size(), 5);  // the bound is per worker (its share is 9)
}

// The frame's end: a worker that would idle gets the tiles another has held longest (over
// kBackupAfterSeconds) once more, the same tasks; the first result merged ends both leases.
TEST_F(DispatcherTest, AtTheFramesEndAnIdleWorkerBacksUpTheOldestLeases) {
  const std::shared_ptr<Job> job = add_still();
  const uint64_t far = add_worker(1);
  const v1::GetTaskResponse held = get(far);  // every tile, as the only worker
  ASSERT_EQ(held.tasks_size(), int(kTiles));
  const uint64_t near = add_worker(1);
  now += 0.1;
  EXPECT_EQ(get(near).tasks_size(), 0);  // not yet: the far worker may still be on time
  now += Dispatcher::kBackupAfterSeconds;
  // Within the request's sample limit, as any task: the first backup reaches it.
  const v1::GetTaskResponse one = get(near, Dispatcher::kMaxTasksPerRequest, 1);
  ASSERT_EQ(one.tasks_size(), 1);
  EXPECT_EQ(one.tasks(0).tile().x(), held.tasks(0).tile().x());
  EXPECT_EQ(one.tasks(0).tile().y(), held.tasks(0).tile().y());
  leasing.end(one.tasks(0).task_id(), true, now);  // given back: the far worker's lease goes on
  ASSERT_EQ(job->tile_backup.size(), 0u);
  const v1::GetTaskResponse backups = get(near);
  ASSERT_EQ(backups.tasks_size(), int((kTiles + 1) / 2));  // its share of what is outstanding
  for (int i = 0; i < backups.tasks_size(); ++i) {         // the oldest first, the same tasks
    const v1::Task &b = backups.tasks(i), &f = held.tasks(i);
    EXPECT_EQ(b.tile().x(), f.tile().x());
    EXPECT_EQ(b.tile().y(), f.tile().y());
    EXPECT_EQ(b.pass(), f.pass());
    EXPECT_EQ(b.sample_begin(), f.sample_begin());
    EXPECT_EQ(b.sample_end(), f.sample_end());
    EXPECT_NE(b.task_id(), f.task_id());
  }
  EXPECT_EQ(get(near).tasks_size(), 0);  // one backup a tile, within its share
  // The backup's result comes first: merged, and the far worker's lease ends with it.
  const uint64_t tile0 = held.tasks(0).task_id();
  EXPECT_TRUE(submit(result(backups.tasks(0).task_id())).accepted());
  EXPECT_EQ(leases.live(tile0), nullptr);
  EXPECT_TRUE(submit(result(tile0)).duplicate());  // the far worker's, later
  EXPECT_EQ(job->tile_backup.size(), size_t(backups.tasks_size() - 1));
}

TEST_F(DispatcherTest, TheRequestsCountAndSampleLimitsHold) {
  add_still();
  const uint64_t w = add_worker();
  EXPECT_EQ(get(w, 4).tasks_size(), 4);
  EXPECT_EQ(get(w, 0).tasks_size(), 1);  // a count of 0 asks for one
  // The first task holds 1024 samples, under the limit: a second is given, which reaches it.
  EXPECT_EQ(get(w, 100, kFirstPassSamples + 1).tasks_size(), 2);
  EXPECT_EQ(get(w, 100, 1).tasks_size(), 1);  // always one if any is ready
}

TEST_F(DispatcherTest, AtMostMaxTasksPerRequestAreGivenAtOnce) {
  RenderSettings s = testing::small_settings();
  s.tile_size = 1;  // 1728 tiles
  add_still(s);
  EXPECT_EQ(uint32_t(get(add_worker(), 100000).tasks_size()), Dispatcher::kMaxTasksPerRequest);
}

class DispatcherChecksTest : public DispatcherTest {
 protected:
  // The check of worker `first`'s result for the job's first task, as the Verifier issues it.
  uint64_t check_of(Job& job, uint64_t first) {
    v1::Task task;
    task.set_job_id(job.id());
    task.set_task_id(999);
    Check c;
    c.job = job.id();
    c.task = std::make_shared<const v1::Task>(task);
    c.first_worker = first;
    c.since = now;
    ++job.pending_checks;
    return checks.add(std::move(c));
  }
};

TEST_F(DispatcherChecksTest, ChecksGoFirstAndNeverToTheWorkerWhoseResultTheyCheck) {
  Job& job = *add_still();
  const uint64_t a = add_worker(), b = add_worker();
  const uint64_t check = check_of(job, a);
  v1::GetTaskResponse r = get(a, 2);
  ASSERT_EQ(r.tasks_size(), 2);
  for (const v1::Task& t : r.tasks()) EXPECT_EQ(leases.live(t.task_id())->check, 0u);
  EXPECT_EQ(checks.find(check)->lease, 0u);
  r = get(b, 2);
  ASSERT_EQ(r.tasks_size(), 2);
  EXPECT_EQ(r.tasks(0).task_id(), checks.find(check)->lease);  // a new id for the checker's lease
  EXPECT_EQ(leases.live(r.tasks(0).task_id())->check, check);
  EXPECT_EQ(leases.live(r.tasks(1).task_id())->check, 0u);
}

TEST_F(DispatcherTest, ASequencesNextFrameStartsOnceItsStartedFramesHaveNoReadyTask) {
  Sequence& s = add_sequence({3, 4});
  const uint64_t w = add_worker();
  std::vector<std::string> got = job_ids(get(w, kTiles));
  EXPECT_EQ(got, std::vector<std::string>(kTiles, s.frame_job_id(0)));
  EXPECT_EQ(s.frames_started, 1u);
  got = job_ids(get(w, 1));
  EXPECT_EQ(got, std::vector<std::string>{s.frame_job_id(1)});
  EXPECT_EQ(s.frames_started, 2u);
}

TEST_F(DispatcherTest, ASequencesNextFrameComesBeforeLaterJobs) {
  Sequence& s = add_sequence({3, 4});
  const std::string later = add_still()->id();
  const std::vector<std::string> got = job_ids(get(add_worker(), 2 * kTiles + 1));
  ASSERT_EQ(got.size(), 2 * kTiles + 1);
  EXPECT_EQ(got[kTiles - 1], s.frame_job_id(0));
  EXPECT_EQ(got[kTiles], s.frame_job_id(1));
  EXPECT_EQ(got[2 * kTiles], later);
}

class LivePixelsTest : public DispatcherTest {
 protected:
  static CoordinatorOptions with_max_live_pixels(int64_t pixels) {
    CoordinatorOptions o = testing::parts_options();
    o.max_live_pixels = pixels;
    return o;
  }
  explicit LivePixelsTest(int64_t max_live_pixels = int64_t(testing::kPixels))  // one frame's film
      : DispatcherTest(with_max_live_pixels(max_live_pixels)) {}
};

TEST_F(LivePixelsTest, TheLivePixelLimitStopsAFurtherFrame) {
  Sequence& s = add_sequence({3, 4});
  EXPECT_EQ(get(add_worker()).tasks_size(), int(kTiles));  // frame 3 only
  EXPECT_EQ(s.frames_started, 1u);
}

class TinyLivePixelsTest : public LivePixelsTest {
 protected:
  TinyLivePixelsTest() : LivePixelsTest(1) {}
};

TEST_F(TinyLivePixelsTest, TheFirstFrameStartsWhateverTheLimit) {
  Sequence& s = add_sequence({3, 4});
  EXPECT_EQ(get(add_worker()).tasks_size(), int(kTiles));
  EXPECT_EQ(s.frames_started, 1u);
}

TEST_F(DispatcherTest, AnUnknownWorkerMustRegisterAgain) {
  add_still();
  const std::string why = refusal([&] { get(12345); }, Code::kFailedPrecondition);
  EXPECT_EQ(why, "unknown worker 12345; register again");
}

TEST_F(DispatcherTest, AQuarantinedWorkerGetsNothing) {
  add_still();
  const uint64_t w = add_worker();
  checks.quarantine(w);
  const std::string why = refusal([&] { get(w); }, Code::kPermissionDenied);
  EXPECT_TRUE(has(why, "is quarantined")) << why;
  EXPECT_EQ(leases.live_count(), 0u);
}

TEST_F(DispatcherTest, WithNothingToGiveTheWorkerIsToldWhenToAskAgain) {
  const uint64_t w = add_worker();
  const v1::GetTaskResponse r = get(w);
  EXPECT_EQ(r.tasks_size(), 0);
  EXPECT_EQ(r.retry_after_ms(), 200u);
  EXPECT_EQ(worker(w).last_seen, now);
}

TEST_F(DispatcherTest, OverdueLeasesExpireOnTheCall) {
  Job& job = *add_still();
  const uint64_t a = add_worker(), b = add_worker();
  const uint64_t t = get(a, 1).tasks(0).task_id();
  now += options.lease_seconds + 1;
  fx = {};
  const v1::GetTaskResponse r = get(b, 1);
  EXPECT_EQ(counters.leases_expired, 1u);
  EXPECT_TRUE(fx.changed);
  EXPECT_EQ(leases.live(t), nullptr);
  ASSERT_EQ(r.tasks_size(), 1);
  EXPECT_EQ(from_proto(r.tasks(0).tile()), job.plan.tiles()[0]);  // a's tile, again
}

// A worker on a slow link asks for runs of passes (GetTaskRequest.max_passes): it gets a
// tile's remaining passes in one task with the tile's sums so far, and its result, those
// sums and the run's passes added to them, takes the tile's place.
TEST_F(DispatcherTest, ARunOfPassesCarriesTheTilesSumsAndItsResultTakesTheirPlace) {
  const std::shared_ptr<Job> job = add_still();
  testing::merge_passes(job->plan, 1);  // every tile has its first pass
  const uint64_t w = add_worker();
  const v1::GetTaskResponse r = dispatcher.get_task(w, 1, 0, now, fx, 8);
  ASSERT_EQ(r.tasks_size(), 1);
  const v1::Task& t = r.tasks(0);
  EXPECT_EQ(t.pass(), 1u);
  EXPECT_EQ(t.pass_count(), 2u);  // the two passes left
  EXPECT_EQ(t.sample_begin(), 4u);
  EXPECT_EQ(t.sample_end(), 10u);
  EXPECT_EQ(worker(w).passes_per_task, 8u);  // shown on the status page
  const Lease* lease = leases.live(t.task_id());
  ASSERT_NE(lease, nullptr);
  EXPECT_EQ(lease->pass_count, 2u);
  const uint32_t tile = lease->tile;
  const std::vector<PixelSums> first = testing::plausible_sums(job->plan, tile, 0);
  std::vector<PixelSums> sums = task_base(t, from_proto(t.tile()), 1);
  ASSERT_EQ(sums.size(), first.size());
  for (size_t i = 0; i < sums.size(); ++i) EXPECT_EQ(sums[i].r, first[i].r) << i;
  for (uint32_t pass : {1u, 2u}) {
    const std::vector<PixelSums> more = testing::plausible_sums(job->plan, tile, pass);
    for (size_t i = 0; i < sums.size(); ++i) sums[i].add(more[i]);
  }
  v1::TaskResult result;
  result.set_worker_id(w);
  result.set_task_id(t.task_id());
  result.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
  result.set_sums_zstd(encode_sums(sums));
  const uint64_t merged = counters.samples_merged;
  EXPECT_TRUE(submit(result).accepted());
  EXPECT_TRUE(job->plan.progress(tile).finished);
  EXPECT_EQ(counters.samples_merged - merged, uint64_t(6) * uint64_t(job->plan.tiles()[tile].area()));
  EXPECT_EQ(leases.live(t.task_id()), nullptr);  // its lease ended with the merge
  // The same result again is a duplicate; a single-pass request gets single passes.
  EXPECT_TRUE(submit(result).duplicate());
  const v1::GetTaskResponse one = dispatcher.get_task(w, 1, 0, now, fx);
  ASSERT_EQ(one.tasks_size(), 1);
  EXPECT_EQ(one.tasks(0).pass_count(), 0u);
  EXPECT_TRUE(one.tasks(0).base_sums().empty());
}

}  // namespace
}  // namespace tessera
