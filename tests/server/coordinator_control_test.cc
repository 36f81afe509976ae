// Issue 22, the job lifecycle after submit, through the coordinator's public calls: delete
// (the data folder shrinks back), requeue (bit-identical, from what is on disk), priority,
// retention and paging; each across a restart, and a crash at each commit point.
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

using testing::files_under;

// Renders tasks until `n` results are merged (or none is left).
void merge_some(Coordinator& c, uint64_t w, int n, const std::function<v1::TaskResult(const v1::Task&)>& render) {
  for (int i = 0; i < n; ++i) {
    const v1::GetTaskResponse r = c.get_task(w);
    if (r.tasks_size() == 0) return;
    ASSERT_TRUE(c.submit_result(render(r.tasks(0))).accepted());
  }
}

class ControlTest : public CoordinatorTest {
 protected:
  std::function<v1::TaskResult(const v1::Task&)> by(uint64_t w) {
    return [this, w](const v1::Task& t) { return render_task(t, w); };
  }
};

TEST_F(ControlTest, DeletingAnEndedJobLeavesNothingOnDisk) {
  const std::string id = c->submit(request(job_settings()));
  drain(worker());
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const size_t before = files_under(dir + "/jobs") + files_under(dir + "/scenes");
  EXPECT_GE(before, 3u);  // image, checkpoint, the scene's manifest and files
  EXPECT_GT(c->remove(id), 0u);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
  EXPECT_EQ(refused([&] { c->status(id, false); }), RequestError::Code::kNotFound);
  EXPECT_TRUE(c->list().empty());
  EXPECT_EQ(c->counters().jobs_deleted, 1u);
  restart(c, options(), &t);
  EXPECT_TRUE(c->list().empty());
  EXPECT_EQ(refused([&] { c->remove(id); }), RequestError::Code::kNotFound);
}

TEST_F(ControlTest, DeletingALiveJobCancelsItAndItsLeasesEnd) {
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  merge_some(*c, w, 2, by(w));
  const v1::Task held = c->get_task(w).tasks(0);
  c->remove(id);
  EXPECT_FALSE(c->heartbeat(w, held.task_id()));
  EXPECT_FALSE(c->submit_result(render_task(held, w)).accepted());
  EXPECT_EQ(c->get_task(w).tasks_size(), 0);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
  restart(c, options(), &t);
  EXPECT_TRUE(c->list().empty());
}

// A delete waits for the job's writer to stop (its next band sees the job removed), then
// removes everything; the writer says when it stops (Coordinator::write notifies then: a
// delete racing it on an idle farm could otherwise wait out kImageWaitSeconds).
TEST_F(ControlTest, ADeleteWaitsForAWriteUnderWayAndNoLonger) {
  CoordinatorOptions o = options();
  o.checkpoint_seconds = 0;  // every merge asks for a checkpoint, written on the merging thread
  std::atomic<bool> writing{false};
  o.before_checkpoint_rename = [&] {
    writing = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  };
  restart(c, o, &t);
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const v1::TaskResult result = render_task(c->get_task(w).tasks(0), w);
  std::thread merger([&] { c->submit_result(result); });  // its checkpoint is written on this thread
  for (int i = 0; i < 10000 && !writing; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_TRUE(writing) << "no write began";
  const auto start = std::chrono::steady_clock::now();
  c->remove(id);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 30);
  merger.join();
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
}

TEST_F(ControlTest, ADeletedSequenceTakesEveryFramesFiles) {
  v1::SubmitJobRequest r = request(job_settings());
  for (int f : {1, 2, 3}) r.add_frames(f);
  const std::string id = c->submit(r);
  const uint64_t w = worker();
  merge_some(*c, w, 20, by(w));  // some frames done, one under way
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_GT(files_under(dir + "/jobs"), 0u);
  c->remove(id);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
  EXPECT_EQ(refused([&] { c->status(id + "-f1", false); }), RequestError::Code::kNotFound);
}

TEST_F(ControlTest, OnlyTheOwnerOrAnAdminChangesAJobAndFramesAreChangedThroughTheirSequence) {
  v1::SubmitJobRequest r = request(job_settings());
  const std::string id = c->submit(r, "ann");
  for (int f : {1, 2}) r.add_frames(f);
  r.set_priority(1);  // its first frame starts first
  const std::string seq = c->submit(r, "ann");
  const uint64_t w = worker();
  merge_some(*c, w, 1, by(w));
  for (const std::string& j : {id, seq}) {
    EXPECT_EQ(refused([&] { c->remove(j, "bob", false); }), RequestError::Code::kPermissionDenied);
    EXPECT_EQ(refused([&] { c->requeue(j, "bob", false); }), RequestError::Code::kPermissionDenied);
    EXPECT_EQ(refused([&] { c->set_priority(j, 5, "bob", false); }), RequestError::Code::kPermissionDenied);
  }
  EXPECT_EQ(c->set_priority(id, 5, "ann", false).priority(), 5);
  EXPECT_EQ(c->set_priority(id, 6, "root", true).priority(), 6);
  // A live job, a DONE job, a frame: not requeued.
  EXPECT_EQ(refused([&] { c->requeue(id, "ann", false); }), RequestError::Code::kFailedPrecondition);
  c->cancel(seq);
  ASSERT_TRUE(c->wait_for_end(seq, 10));
  const std::string frame = c->status(seq, false).frames(0).job_id();
  ASSERT_FALSE(frame.empty());
  EXPECT_EQ(refused([&] { c->requeue(frame); }), RequestError::Code::kFailedPrecondition);
  EXPECT_EQ(refused([&] { c->remove(frame); }), RequestError::Code::kFailedPrecondition);
  drain(w);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(refused([&] { c->requeue(id); }), RequestError::Code::kFailedPrecondition);
  EXPECT_EQ(refused([&] { c->requeue("nope"); }), RequestError::Code::kNotFound);
}

// A cancelled job taken up again renders only what it had not, and its image is the one an
// uninterrupted render makes, bit for bit; so is a failed one's.
TEST_F(ControlTest, ARequeuedJobGoesOnFromItsCheckpointBitIdentically) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const uint64_t w = worker();
  merge_some(*c, w, 5, by(w));
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const uint64_t merged = c->counters().results_merged;
  const v1::JobStatus st = c->requeue(id);
  EXPECT_EQ(st.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.samples_done(), c->counters().samples_merged);
  drain(w);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->counters().results_merged - merged, size_t(s.tile_count()) * 3 - 5);  // 3 passes a tile
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  EXPECT_EQ(c->counters().jobs_requeued, 1u);
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
}

TEST_F(ControlTest, ARequeuedSequenceRendersItsUnfinishedFramesOnly) {
  const RenderSettings s = job_settings();
  v1::SubmitJobRequest r = request(s);
  for (int f : {1, 2, 3}) r.add_frames(f);
  const std::string id = c->submit(r);
  const uint64_t w = worker();
  merge_some(*c, w, int(s.tile_count()) * 3 + 2, by(w));  // frame 1 done, frame 2 begun
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_EQ(c->status(id, false).frames_done(), 1u);
  c->requeue(id);
  drain(w);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.frames_done(), 3u);
  for (int f : {1, 2, 3}) {
    RenderSettings frame = s;
    frame.frame = f;
    EXPECT_TRUE(same_film_as_exr(local(frame), read_exr(image_path(id + "-f" + std::to_string(f), "image.exr")))) << f;
  }
}

// kill -9 just after a requeue's record (here: the row says QUEUED, then the step throws, as
// if the process died): the restart takes the job up from its checkpoint.
TEST_F(ControlTest, ACrashRightAfterARequeuesRecordStillFinishesTheJob) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const uint64_t w = worker();
  merge_some(*c, w, 4, by(w));
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  CoordinatorOptions o = options();
  o.after_row_commit = [] { throw std::runtime_error("killed"); };
  restart(c, o, &t);
  EXPECT_ANY_THROW(c->requeue(id));
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::RUNNING);
  drain(worker());
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// ... and just after a delete's record: the restart finds no job and removes its files.
TEST_F(ControlTest, ACrashRightAfterADeletesRecordLeavesNothingAfterTheRestart) {
  const std::string id = c->submit(request(job_settings()));
  drain(worker());
  ASSERT_TRUE(c->wait_for_end(id, 10));
  CoordinatorOptions o = options();
  o.after_row_commit = [] { throw std::runtime_error("killed"); };
  restart(c, o, &t);
  EXPECT_ANY_THROW(c->remove(id));
  EXPECT_GT(files_under(dir + "/jobs"), 0u);  // the row is gone; the files were not reached
  restart(c, options(), &t);
  EXPECT_EQ(refused([&] { c->status(id, false); }), RequestError::Code::kNotFound);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
}

TEST_F(ControlTest, APriorityChangeReordersTheQueueAndSurvivesARestart) {
  const std::string a = c->submit(request(job_settings())), b = c->submit(request(job_settings()));
  c->set_priority(b, 10);
  restart(c, options(), &t);
  EXPECT_EQ(c->status(b, false).priority(), 10);
  const uint64_t w = worker();
  const v1::Task first = c->get_task(w).tasks(0);
  EXPECT_EQ(first.job_id(), b);
  EXPECT_EQ(c->status(a, false).state(), v1::JobStatus::QUEUED);
}

TEST_F(ControlTest, JobsArePagedInSubmissionOrder) {
  std::vector<std::string> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(c->submit(request(job_settings())));
  std::vector<std::string> seen;
  std::string token;
  int pages = 0;
  do {
    const v1::JobList page = c->list(2, token);
    EXPECT_EQ(page.total(), 5u);
    for (const auto& j : page.jobs()) seen.push_back(j.id());
    token = page.next_page_token();
    ++pages;
  } while (!token.empty());
  EXPECT_EQ(seen, ids);
  EXPECT_EQ(pages, 3);
  EXPECT_EQ(c->list(0, "").jobs_size(), 5);
  c->remove(ids[2]);
  EXPECT_EQ(c->list(2, c->list(2, "").next_page_token()).jobs(0).id(), ids[3]);
  EXPECT_EQ(refused([&] { c->list(2, "x1"); }), RequestError::Code::kInvalidArgument);
}

// --keep-ended: the ended jobs whose end was recorded longer ago than that, oldest first.
TEST_F(ControlTest, RetentionNamesJobsEndedLongerAgoThanTheLimit) {
  auto store = std::make_unique<MemoryJobStore>();
  MemoryJobStore* rows = store.get();
  double wall = 1e9;
  rows->wall = [&wall] { return wall; };
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t), std::make_unique<MemoryImageSink>(),
                                    std::move(store));
  const std::string a = c->submit(request(job_settings()));
  const std::string live = c->submit(request(job_settings()));
  c->cancel(a);
  ASSERT_TRUE(c->wait_for_end(a, 10));
  wall += 30;
  EXPECT_TRUE(c->ended_before(60).empty());
  wall += 31;
  EXPECT_EQ(c->ended_before(60), std::vector<std::string>{a});
  c->remove(a);
  EXPECT_TRUE(c->ended_before(0).empty());
  EXPECT_EQ(c->list().size(), 1u);
  EXPECT_EQ(c->list()[0].id(), live);
}

}  // namespace
}  // namespace tessera
