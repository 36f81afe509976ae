// Verify by replay through the whole coordinator: liars caught, honest workers not.
#include "server/secrets.h"
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

// ---- verify by replay -------------------------------------------------------------------

// Plausible sums that are not the render's: what a subtly broken or dishonest worker sends.
v1::TaskResult lie(v1::TaskResult r) {
  const size_t n = r.raw_size() / kBytesPerPixel;
  std::vector<PixelSums> sums = decode_sums(r.sums_zstd(), n);
  for (PixelSums& p : sums) p = PixelSums{p.r * 0.8, p.g * 0.8, p.b * 0.8, p.lum2 * 0.64, p.n};
  r.set_sums_zstd(encode_sums(sums));
  return r;
}

class VerifyTest : public CoordinatorTest {
 protected:
  void SetUp() override {}
  void start(double fraction) {
    CoordinatorOptions o = options();
    o.verify_fraction = fraction;
    c.reset();  // (the old one lets the data folder go first)
    c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  }
  // A worker enrolled under `name` (its own credential, as deploy recipes run them).
  uint64_t worker_as(const std::string& name) {
    credential[name] = c->enrol(name, "farm-enrol");
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name(name);
    return c->register_worker(r, name, true).worker_id();
  }
  bool credential_refused(const std::string& name) {
    const auto h = c->credentials().find(sha256(credential.at(name)));
    return !h || h->quarantined;
  }
  std::map<std::string, std::string> credential;
  // A job of job_settings() a lying worker merges three lies into, then CANCELLED (and
  // `requeued` at once, or not), and another job (seed 17) the liar will be caught on.
  std::string cancelled_with_lies(uint64_t* honest, uint64_t* liar, bool requeued) {
    start(0.5);
    RenderSettings other = job_settings();
    other.seed = 17;
    *honest = worker_as("honest"), *liar = worker_as("liar");
    const std::string id = c->submit(request(job_settings()));
    for (int k = 0; k < 3; ++k) EXPECT_TRUE(step(*liar, true));
    c->cancel(id);
    EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::CANCELLED);
    if (requeued) c->requeue(id);
    c->submit(request(other));
    return id;
  }
  // One task for worker w, rendered (and falsified if `lying`) and returned; false if it
  // got none or is refused.
  bool step(uint64_t w, bool lying) {
    v1::GetTaskResponse r;
    try {
      r = c->get_task(w, 1);
    } catch (const RequestError&) {
      return false;
    }
    if (r.tasks_size() == 0) return false;
    const v1::TaskResult res = render_task(r.tasks(0), w);
    c->submit_result(lying ? lie(res) : res);
    return true;
  }
  // Both workers take turns until every job has ended; time moves on when neither has
  // work (expiring leases and checks nobody else can take).
  void run(uint64_t honest, uint64_t liar, bool lying) {
    for (int guard = 0; guard < 20000; ++guard) {
      bool any_live = false;
      for (const v1::JobStatus& j : c->list())
        any_live |= j.state() == v1::JobStatus::QUEUED || j.state() == v1::JobStatus::RUNNING;
      if (!any_live) return;
      const bool a = step(honest, false), b = step(liar, lying);
      if (!a && !b) {
        t += 11;
        c->expire_leases();
      }
    }
    FAIL() << "jobs did not end";
  }
};

TEST_F(VerifyTest, HonestWorkersPassEveryCheckAndTheImageIsUnchanged) {
  start(1.0);
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const double t0 = t;
  run(worker(), worker(), false);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  // Checks count in the workers' shares: the last ones are taken at once, and the job
  // never waits for a check to be skipped (time never had to move on).
  EXPECT_EQ(t, t0);
  const CoordinatorCounters k = c->counters();
  EXPECT_GT(k.checks_issued, 10u);
  EXPECT_EQ(k.checks_passed, k.checks_issued);
  EXPECT_EQ(k.checks_skipped, 0u);
  EXPECT_EQ(k.check_mismatches, 0u);
  EXPECT_EQ(k.workers_quarantined, 0u);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(VerifyTest, ALyingWorkerIsQuarantinedAndWhatItMergedIsRenderedAgain) {
  start(0.5);  // 27 tasks a job: the chance that no task of the liar's is checked is 2^-27
  const RenderSettings s = job_settings();
  RenderSettings other = s;
  other.seed = 17;
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string before = c->submit(request(other));
  run(honest, liar, false);  // the liar is honest at first: a job with its results ends DONE
  ASSERT_EQ(c->status(before, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->counters().workers_quarantined, 0u);
  const std::string id = c->submit(request(s));
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(step(liar, true));  // lies merged before anyone checks
  run(honest, liar, true);
  const CoordinatorCounters k = c->counters();
  EXPECT_EQ(k.workers_quarantined, 1u);
  EXPECT_GE(k.check_mismatches, 1u);
  EXPECT_GE(k.tiles_rendered_again, 3u);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  // Every lie it got merged was rendered again: the image is the honest one, bit for bit.
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // It gets no more work, its credential is refused and its name may not enrol again; the
  // honest one goes on.
  EXPECT_THROW(c->get_task(liar), RequestError);
  EXPECT_TRUE(credential_refused("liar"));
  EXPECT_FALSE(credential_refused("honest"));
  EXPECT_THROW(c->enrol("liar", "farm-enrol"), RequestError);
  EXPECT_NO_THROW(c->get_task(honest));
  // The job that ended before it was caught is flagged, not silently trusted.
  const std::string flag = c->status(before, false).error();
  EXPECT_NE(flag.find("quarantined"), std::string::npos) << flag;
  EXPECT_EQ(c->status(id, false).error(), "");
}

// Jobs that left memory (archive.h) before the liar was caught are flagged in their rows:
// a still, and a sequence with frames the liar rendered.
TEST_F(VerifyTest, ArchivedJobsHoldingALiarsResultsAreFlaggedInTheirRows) {
  start(0.5);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string still = c->submit(request(s));
  v1::SubmitJobRequest r = request(s);
  for (int f : {1, 2}) r.add_frames(f);
  const std::string sequence = c->submit(r);
  run(honest, liar, false);  // honest at first: both end DONE with its results in them
  for (int i = 0; i < 200 && !c->list().empty(); ++i) {
    c->expire_leases();  // the reaper's tick archives them
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(c->list().empty()) << "not archived";
  const std::string id = c->submit(request(s));
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(step(liar, true));
  run(honest, liar, true);
  ASSERT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_EQ(c->status(id, false).error(), "");
  const std::string flag = c->status(still, false).error();
  EXPECT_NE(flag.find("tiles hold results of worker 'liar'"), std::string::npos) << flag;
  const std::string frames = c->status(sequence, false).error();
  EXPECT_NE(frames.find("tiles of finished frames hold results of worker 'liar'"), std::string::npos) << frames;
  restart(c, options(), &t);  // the flag is in the row
  EXPECT_EQ(c->status(still, false).error(), flag);
}

// Issue 23: probation. With a fraction that would almost never pick a task, a worker that
// lies from its first task is still caught: every registration's first verify_first tasks
// are checked, and a job does not end before its checks are decided, so no lie stays in
// the image. Its credential is refused from then on; the honest worker's is not.
TEST_F(VerifyTest, AWorkerLyingFromItsFirstTaskIsCaughtOnProbation) {
  start(1e-12);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string id = c->submit(request(s));
  run(honest, liar, true);
  EXPECT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_TRUE(credential_refused("liar"));
  EXPECT_FALSE(credential_refused("honest"));
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(id, false).error(), "");
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // Past probation, the fraction decides: the honest worker's fifth task is not checked.
  EXPECT_LE(c->counters().checks_issued, 2u * CoordinatorOptions{}.verify_first);
}

// A worker on probation that gets only backups of others' tiles (it joined at a frame's
// end) and returns first: its backups are its first merged results, so they are checked.
TEST_F(VerifyTest, BackupsOfAWorkerOnProbationAreChecked) {
  start(1e-12);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest");
  const std::string id = c->submit(request(s));
  std::vector<v1::Task> held;  // alone, the honest worker takes every task and sits on them
  for (v1::GetTaskResponse r; (r = c->get_task(honest, 256)).tasks_size() > 0;)
    held.insert(held.end(), r.tasks().begin(), r.tasks().end());
  const uint64_t liar = worker_as("liar");
  t += 1;  // old enough to back up
  const v1::GetTaskResponse backups = c->get_task(liar, 256);
  ASSERT_GE(backups.tasks_size(), int(CoordinatorOptions{}.verify_first));
  for (const v1::Task& task : backups.tasks()) ASSERT_TRUE(c->submit_result(lie(render_task(task, liar))).accepted());
  EXPECT_EQ(c->counters().checks_issued, CoordinatorOptions{}.verify_first);
  for (const v1::Task& task : held) c->submit_result(render_task(task, honest));  // the backed-up ones: too late
  run(honest, liar, true);
  EXPECT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// A probation task whose lease ends without its result merged (a backup won, or it
// expired) is given back to the worker's probation: its next tasks are checked instead.
TEST_F(VerifyTest, ProbationTasksLostToABackupAreCheckedLater) {
  start(1e-12);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string first = c->submit(request(s));
  const uint32_t n = CoordinatorOptions{}.verify_first;
  ASSERT_EQ(c->get_task(liar, n).tasks_size(), int(n));  // its probation tasks, never returned
  t += 1;
  drain(honest);  // everything, backups of the liar's tiles included
  EXPECT_EQ(c->counters().backup_leases, n);
  run(honest, liar, false);  // the honest worker's own probation checks
  ASSERT_EQ(c->status(first, false).state(), v1::JobStatus::DONE);
  ASSERT_EQ(c->counters().workers_quarantined, 0u);
  const std::string id = c->submit(request(s));
  run(honest, liar, true);  // it lies from now on: its first merged tasks are on probation
  EXPECT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// With one token for every worker, a worker that registers again (it was forgotten, or
// restarted) may be the one whose results wait for a check: it never checks a result of a
// registration that ended before it registered, or its lies would confirm themselves.
TEST_F(VerifyTest, AWorkerRegisteredAgainNeverChecksAnEarlierRegistrationsResults) {
  start(1e-12);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker(), liar = worker();
  const std::string id = c->submit(request(s));
  const uint32_t n = CoordinatorOptions{}.verify_first;
  for (uint32_t k = 0; k < n; ++k) ASSERT_TRUE(step(liar, true));  // merged, waiting for checks
  ASSERT_EQ(c->counters().checks_issued, n);
  c->unregister(liar);
  const uint64_t again = worker();
  const v1::GetTaskResponse r = c->get_task(again, 256);
  ASSERT_GT(r.tasks_size(), 0);
  for (const v1::Task& task : r.tasks()) c->submit_result(lie(render_task(task, again)));
  EXPECT_EQ(c->counters().checks_passed, 0u);  // it got none of its earlier lies to confirm
  run(honest, again, true);
  EXPECT_EQ(c->counters().checks_passed, 0u);
  EXPECT_EQ(c->counters().workers_quarantined, 2u);  // both registrations, by the honest worker's checks
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(VerifyTest, AWorkerLyingOnlyAsTheCheckerIsTheOneQuarantined) {
  start(1.0);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string id = c->submit(request(s));
  // The honest worker renders first; the liar gets only checks of its results, and lies.
  ASSERT_TRUE(step(honest, false));
  ASSERT_EQ(c->counters().checks_issued, 1u);
  // The liar's first task is the check of the honest worker's result (checks go first).
  const v1::GetTaskResponse r = c->get_task(liar, 1);
  ASSERT_EQ(r.tasks_size(), 1);
  c->submit_result(lie(render_task(r.tasks(0), liar)));
  EXPECT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_THROW(c->get_task(liar), RequestError);
  EXPECT_NO_THROW(c->get_task(honest));
  run(honest, honest, false);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// A check's result that does not decode is refused, saying why, and decides nothing: its
// worker may still send the render, which is checked as any other.
TEST_F(VerifyTest, ACheckResultThatDoesNotDecodeIsRefusedSayingWhy) {
  start(1.0);
  const RenderSettings s = job_settings();
  const uint64_t first = worker_as("first"), checker = worker_as("checker");
  const std::string id = c->submit(request(s));
  ASSERT_TRUE(step(first, false));
  ASSERT_EQ(c->counters().checks_issued, 1u);
  const v1::GetTaskResponse r = c->get_task(checker, 1);  // checks go first
  ASSERT_EQ(r.tasks_size(), 1);
  const v1::TaskResult honest = render_task(r.tasks(0), checker);
  v1::TaskResult broken = honest;
  broken.set_sums_zstd("not zstd at all");
  const v1::ResultAck ack = c->submit_result(broken);
  EXPECT_FALSE(ack.accepted());
  EXPECT_NE(ack.refused().find("result refused: "), std::string::npos) << ack.refused();
  EXPECT_GT(ack.refused().size(), std::string("result refused: ").size()) << ack.refused();
  EXPECT_EQ(c->counters().results_rejected, 1u);
  EXPECT_EQ(c->counters().checks_passed, 0u);
  EXPECT_EQ(c->counters().check_mismatches, 0u);
  EXPECT_TRUE(c->submit_result(honest).accepted());
  EXPECT_EQ(c->counters().checks_passed, 1u);
  EXPECT_EQ(c->counters().workers_quarantined, 0u);
  run(first, checker, false);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(VerifyTest, NoChecksWithOneWorkerOrAZeroFraction) {
  start(0);
  const std::string id = c->submit(request(job_settings()));
  run(worker(), worker(), false);
  EXPECT_EQ(c->counters().checks_issued, 0u);
  start(1.0);
  const std::string alone = c->submit(request(job_settings()));
  const uint64_t w = worker();
  drain(w);
  EXPECT_EQ(c->status(alone, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->counters().checks_issued, 0u);
  (void)id;
}

// The autoscaling signal: what is left, in tasks, samples and core-seconds.

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a liar caught while a job it merged into was CANCELLED left its results
// in the job (only live jobs were reset, only DONE ones flagged), and a requeue finished
// the job DONE with them, unflagged. Now the job is flagged and its requeue renders those
// tiles again: the image is the honest one, bit for bit.
TEST_F(VerifyTest, ALiarCaughtWhileAJobWasCancelledIsRenderedAgainWhenItIsRequeued) {
  uint64_t honest = 0, liar = 0;
  const std::string id = cancelled_with_lies(&honest, &liar, false);
  run(honest, liar, true);  // caught on the other job
  ASSERT_EQ(c->counters().workers_quarantined, 1u);
  const std::string flag = c->status(id, false).error();
  EXPECT_NE(flag.find("a requeue renders them again"), std::string::npos) << flag;
  c->requeue(id);
  run(honest, liar, false);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(job_settings()), read_exr(image_path(id, "image.exr"))));
}

// ... and one requeued before the liar is caught: the requeued job still knows who merged
// what, so its tiles are rendered again when it is.
TEST_F(VerifyTest, ALiarCaughtAfterARequeueHasItsTilesRenderedAgain) {
  uint64_t honest = 0, liar = 0;
  const std::string id = cancelled_with_lies(&honest, &liar, true);
  run(honest, liar, true);
  ASSERT_EQ(c->counters().workers_quarantined, 1u);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(job_settings()), read_exr(image_path(id, "image.exr"))));
}

}  // namespace
}  // namespace tessera
