// Verifier: verify by replay. A picked task's merged result is rendered again by another
// worker; equal digests pass, different ones go to the Referee (here a lambda), and
// whoever differs from it is quarantined: its leases end, the tiles of live jobs it merged
// into start over, ended jobs are flagged.
#include "server/verifier.h"

#include <gtest/gtest.h>

#include "server/job_status.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::has;
using testing::kTiles;
using testing::plausible_sums;

CoordinatorOptions verifying() {
  CoordinatorOptions o = testing::parts_options();
  o.verify_fraction = 1;
  return o;
}

class VerifierTest : public testing::PartsTest {
 protected:
  VerifierTest() : PartsTest(verifying()) {}
  std::shared_ptr<Job> job = add_still();
  uint64_t a = add_worker(1, "liar"), b = add_worker(1, "checker");

  // `first`'s result for the job's next task, picked for a check and merged; the check's id.
  uint64_t merged_and_picked(Job& j, uint64_t first) {
    const uint64_t t = lease_next(j, first);
    leases.live(t)->task = std::make_shared<const v1::Task>();
    const size_t before = checks.all().size();
    EXPECT_TRUE(submit(result(t)).accepted());
    EXPECT_EQ(checks.all().size(), before + 1);
    return checks.all().rbegin()->first;  // ids count up
  }
  // The check leased to the checker, as GetTask leases it; the lease's id.
  uint64_t lease_check(uint64_t checker) {
    v1::GetTaskResponse out;
    verifier.lease_checks(worker(checker), 1, now, out);
    EXPECT_EQ(out.tasks_size(), 1);
    return out.tasks_size() ? out.tasks(0).task_id() : 0;
  }
  // The digest of the sums a worker rendering (tile, pass) with this value sends.
  uint64_t digest(uint32_t tile, uint32_t pass, double value) const {
    return sums_digest(plausible_sums(job->plan, tile, pass, value));
  }
  // A run's result (passes 1 and 2 of a tile after its first): its sums grown to 10 samples
  // a pixel from plausible_sums' first pass, at the same luminance.
  v1::TaskResult run_result(uint64_t task) const {
    const Lease* l = leases.known(task);
    std::vector<PixelSums> sums = plausible_sums(job->plan, l->tile, 0);
    for (PixelSums& p : sums) {
      const double v = p.r / p.n;
      p = PixelSums{10 * v, 10 * v, 10 * v, 10 * v * v, 10};
    }
    v1::TaskResult r = result(task);
    r.set_sums_zstd(encode_sums(sums));
    r.set_samples(r.samples() / 4 * 6);
    return r;
  }
  // Pass `pass` of every tile leased to the worker and merged.
  void render_pass(uint32_t pass, uint64_t w) {
    for (uint32_t t = 0; t < kTiles; ++t) {
      const uint64_t id = lease_next(*job, w);
      ASSERT_EQ(leases.known(id)->pass, pass);
      ASSERT_TRUE(submit(result(id)).accepted());
    }
  }
  // A referee that renders (tile 0, pass 0) as a worker sending `value` does.
  Referee renders(double value) const {
    const std::vector<PixelSums> sums = plausible_sums(job->plan, 0, 0, value);
    return [sums](const v1::Task&) { return sums; };
  }
};

TEST_F(VerifierTest, ItNeedsASecondWorkerAndAFraction) {
  EXPECT_TRUE(verifier.active());
  workers.remove(b);
  EXPECT_FALSE(verifier.active());
  add_worker();
  const Verifier off(0, options.lease_seconds, checks, jobs, leasing, workers, lifecycle, counters);
  EXPECT_FALSE(off.active());
}

TEST_F(VerifierTest, AnIssuedCheckWaitsForAnotherWorkerAndHoldsTheJobOpen) {
  testing::merge_passes(job->plan, testing::kPasses);  // every tile merged
  Lease l{job->id(), 4, 2, a, now + 5, std::make_shared<const v1::Task>()};
  verifier.issue(*job, l, a, 1234, now);
  ASSERT_EQ(checks.all().size(), 1u);
  const Check& c = checks.all().begin()->second;
  EXPECT_EQ(c.job, job->id());
  EXPECT_EQ(c.tile, 4u);
  EXPECT_EQ(c.pass, 2u);
  EXPECT_EQ(c.task, l.task);
  EXPECT_EQ(c.first_worker, a);
  EXPECT_EQ(c.digest, 1234u);
  EXPECT_EQ(c.lease, 0u);
  EXPECT_EQ(c.since, now);
  EXPECT_EQ(job->pending_checks, 1u);
  EXPECT_EQ(counters.checks_issued, 1u);
  EXPECT_FALSE(lifecycle.finish_if_done(*job, now, fx));
}

TEST_F(VerifierTest, ChecksGoOnlyWhileWaitingNeverToTheirFirstWorkerAndUpToMax) {
  for (int i = 0; i < 3; ++i) merged_and_picked(*job, a);
  const uint64_t c = add_worker();
  v1::GetTaskResponse out;
  verifier.lease_checks(worker(a), 5, now, out);
  EXPECT_EQ(out.tasks_size(), 0);  // its own results
  verifier.lease_checks(worker(b), 1, now, out);
  ASSERT_EQ(out.tasks_size(), 1);
  const Check& first = checks.all().begin()->second;
  EXPECT_EQ(out.tasks(0).task_id(), first.lease);
  EXPECT_EQ(leases.live(first.lease)->worker, b);
  verifier.lease_checks(worker(c), 5, now, out);  // `max` counts what `out` holds
  EXPECT_EQ(out.tasks_size(), 3);
  verifier.lease_checks(worker(b), 5, now, out);
  EXPECT_EQ(out.tasks_size(), 3);  // none waiting
  EXPECT_EQ(checks.waiting(), 0u);
}

// Found by review: a worker resting from a job (its task of it failed lately:
// JobLifecycle::task_failed) was still given the job's checks, which would fail there too.
TEST_F(VerifierTest, NoChecksGoToAWorkerRestingFromTheirJob) {
  merged_and_picked(*job, a);
  lifecycle.task_failed(*job, worker(b), "out of memory", now, fx);
  v1::GetTaskResponse out;
  verifier.lease_checks(worker(b), 1, now, out);
  EXPECT_EQ(out.tasks_size(), 0);
  now += JobLifecycle::kFirstRestSeconds;
  verifier.lease_checks(worker(b), 1, now, out);
  EXPECT_EQ(out.tasks_size(), 1);
}

TEST_F(VerifierTest, EqualDigestsPassAndTheJobEndsOnceItsChecksAreDecided) {
  testing::merge_passes(job->plan, testing::kPasses);
  Lease l{job->id(), 0, 0, a, now + 5, std::make_shared<const v1::Task>()};
  verifier.issue(*job, l, a, 1234, now);
  const uint64_t check = checks.all().begin()->first;
  const uint64_t lease = lease_check(b);
  const Referee never = [](const v1::Task&) -> std::vector<PixelSums> {
    ADD_FAILURE() << "the referee is asked only when two workers differ";
    return {};
  };
  const Verifier::Verdict v = Verifier::judge(*verifier.pending(check, lease), 1234, b, never);
  EXPECT_TRUE(v.same);
  EXPECT_TRUE(v.liars.empty());
  EXPECT_TRUE(verifier.decide(check, lease, b, v, now, fx));
  EXPECT_EQ(counters.checks_passed, 1u);
  EXPECT_EQ(checks.find(check), nullptr);
  EXPECT_EQ(leases.live(lease), nullptr);
  EXPECT_EQ(job->pending_checks, 0u);
  EXPECT_EQ(job->state(), v1::JobStatus::DONE);
  EXPECT_FALSE(verifier.decide(check, lease, b, v, now, fx));  // decided once
}

TEST_F(VerifierTest, AnEnrolledLiarsCredentialIsQuarantined) {
  worker(a).enrolled = true;
  fx = {};
  verifier.quarantine(a, "a test", now, fx);
  ASSERT_EQ(fx.credentials_quarantined.size(), 1u);
  EXPECT_EQ(fx.credentials_quarantined[0].first, "liar");
  EXPECT_EQ(fx.credentials_quarantined[0].second, "a test");
}

TEST_F(VerifierTest, OnlyTheChecksCurrentLeaseDecidesIt) {
  const uint64_t check = merged_and_picked(*job, a);
  const uint64_t lease = lease_check(b);
  EXPECT_FALSE(verifier.pending(check, lease + 1));
  EXPECT_TRUE(verifier.pending(check, lease));
  EXPECT_FALSE(verifier.decide(check, lease + 1, b, Verifier::Verdict{}, now, fx));
  EXPECT_NE(checks.find(check), nullptr);
}

TEST_F(VerifierTest, AWorkerTheRefereeDisagreesWithIsQuarantinedAndItsWorkUndone) {
  // Before it is caught: a job it rendered alone ended DONE.
  const std::shared_ptr<Job> before = add_still();
  render_all(*before, a);
  ASSERT_EQ(before->state(), v1::JobStatus::DONE);
  // In the live job: its results for tiles 0 and 1 merged (both picked), a lease on tile 2.
  const uint64_t check = merged_and_picked(*job, a);
  const uint64_t moot = merged_and_picked(*job, a);
  const uint64_t held = lease_next(*job, a);
  const uint64_t other = lease_next(*job, b);
  ASSERT_EQ(job->pending_checks, 2u);
  // b renders tile 0 differently (value 0.7), and so does the referee.
  const uint64_t lease = lease_check(b);
  const Verifier::Verdict v = Verifier::judge(*verifier.pending(check, lease), digest(0, 0, 0.7), b, renders(0.7));
  EXPECT_FALSE(v.same);
  EXPECT_EQ(v.liars, std::vector<uint64_t>{a});
  fx = {};
  EXPECT_TRUE(verifier.decide(check, lease, b, v, now, fx));  // the checker's result counts
  EXPECT_TRUE(verifier.quarantined(a));
  EXPECT_FALSE(verifier.quarantined(b));
  // A token from the file (possibly every worker's) is never quarantined: only an enrolled
  // worker's own credential is (VerifierTest.AnEnrolledLiarsCredentialIsQuarantined).
  EXPECT_TRUE(fx.credentials_quarantined.empty());
  EXPECT_EQ(workers.find(a), nullptr);
  EXPECT_EQ(counters.check_mismatches, 1u);
  EXPECT_EQ(counters.workers_quarantined, 1u);
  // Its lease ended and its tile is ready again; b's lease stands.
  EXPECT_EQ(leases.live(held), nullptr);
  EXPECT_NE(leases.live(other), nullptr);
  // The tiles it merged into start over: no pass merged, no sum left in their pixels.
  for (uint32_t t : {0u, 1u}) {
    EXPECT_EQ(job->plan.progress(t).passes_done, 0u) << t;
    EXPECT_TRUE(job->plan.wants(t, 0)) << t;
    const Rect r = job->plan.tiles()[t];
    EXPECT_EQ(job->plan.film().at(r.x, r.y).n, 0u) << t;
  }
  EXPECT_EQ(job->plan.samples_merged(), 0u);
  EXPECT_EQ(job->plan.ready(), kTiles - 1);  // all but b's tile 3
  EXPECT_EQ(counters.tiles_rendered_again, 2u);
  EXPECT_EQ(job->merged_by.count(a), 0u);
  // The check of tile 1 is moot: the tile is rendered again anyway.
  EXPECT_EQ(checks.find(moot), nullptr);
  EXPECT_EQ(job->pending_checks, 0u);
  EXPECT_TRUE(job->live());
  // The ended job is flagged, and its database row is rewritten after the lock.
  EXPECT_TRUE(has(before->error, "9 tiles hold results of worker 'liar' (token 'liar', " + std::to_string(a) + ")"))
      << before->error;
  ASSERT_EQ(fx.rows.size(), 1u);
  EXPECT_EQ(fx.rows[0].id, before->id());
  EXPECT_EQ(fx.rows[0].state, v1::JobStatus::DONE);
  EXPECT_EQ(fx.rows[0].error, before->error);
  EXPECT_TRUE(fx.changed);
}

// A frame tracing light paths: a liar's splats landed anywhere, among everyone's, and
// cannot be told apart, so the whole frame starts over (its splats gone, every tile's
// passes rendered again) and a checkpoint written across the reset is not kept.
TEST_F(VerifierTest, ALiarsFrameWithSplatsStartsOverWhole) {
  const uint64_t t0 = lease_next(*job, a), t1 = lease_next(*job, b);
  ASSERT_TRUE(submit(result(t0)).accepted());
  ASSERT_TRUE(submit(result(t1)).accepted());
  SplatRecord r;
  r.paths = 7;
  r.entries.push_back({3, {1, 2, 3, 4}});
  job->splats.add(0, 0, {r});
  job->splats.add(1, 0, {r});
  ASSERT_EQ(job->splats.film()->paths(), 14u);
  const uint64_t resets = job->resets;
  fx = {};
  verifier.quarantine(a, "its sums differ", now, fx);
  EXPECT_EQ(job->resets, resets + 1);
  EXPECT_EQ(job->splats.film()->paths(), 0u);
  EXPECT_EQ(job->splats.film()->at(3, 0).rgb[0], 0);
  for (uint32_t t = 0; t < kTiles; ++t) {
    EXPECT_EQ(job->plan.progress(t).passes_done, 0u) << t;
    EXPECT_EQ(job->splats.frontier(t), 0u) << t;
  }
  EXPECT_EQ(job->plan.samples_merged(), 0u);  // the honest worker's tile too
  EXPECT_EQ(counters.tiles_rendered_again, kTiles);
}

// A run of passes carries its tile's sums so far (its base) and returns them grown. One
// leased on a liar's sums and returned after the liar was caught and the tile rendered again
// would put the lie back: a result leased before its tile was taken back is refused.
TEST_F(VerifierTest, AResultLeasedBeforeItsTileWasTakenBackIsRefused) {
  render_pass(0, a);  // every tile's first pass, by the liar
  const std::optional<TileTask> run = job->plan.take(2);
  ASSERT_TRUE(run && run->tile == 0 && run->pass == 1 && run->pass_count == 2 && !run->base.empty());
  const uint64_t late = leasing.grant(*job, *run, worker(b), now);
  fx = {};
  verifier.quarantine(a, "its sums differ", now, fx);
  EXPECT_EQ(leases.live(late), nullptr);
  const v1::TaskResult late_result = run_result(late);  // (its lease is known by its id alone once tile 0 merges)
  ASSERT_TRUE(submit(result(lease_next(*job, b))).accepted());  // tile 0's first pass again
  ASSERT_TRUE(job->plan.wants(0, 1));
  const v1::ResultAck ack = submit(late_result);
  EXPECT_FALSE(ack.accepted());
  EXPECT_TRUE(ack.duplicate());
  EXPECT_EQ(job->plan.progress(0).passes_done, 1u);
  // The same run leased now (after the other tiles' first passes) is merged.
  for (uint32_t t = 1; t < kTiles; ++t) ASSERT_TRUE(submit(result(lease_next(*job, b))).accepted());
  const std::optional<TileTask> again = job->plan.take(2);
  ASSERT_TRUE(again && again->tile == 0 && again->pass == 1);
  EXPECT_TRUE(submit(run_result(leasing.grant(*job, *again, worker(b), now))).accepted());
  EXPECT_EQ(job->plan.progress(0).passes_done, 3u);
}

// BUG (server/verifier.cc, Verifier::quarantine): a sequence's frame that ended DONE with
// a liar's tiles is flagged with a RowEnd for the frame's own id, but a frame has no row in
// the job database (its sequence has): store->end() updates nothing, the flag is lost at
// a restart, and the sequence's status (what clients see) never shows it.
TEST_F(VerifierTest, AnEndedFrameWithALiarsTilesFlagsItsSequence) {
  Sequence& s = add_sequence({1});
  render_all(start_frame(s), a);
  ASSERT_EQ(s.state(), v1::JobStatus::DONE);
  const uint64_t check = merged_and_picked(*job, a);
  const uint64_t lease = lease_check(b);
  const Verifier::Verdict v = Verifier::judge(*verifier.pending(check, lease), digest(0, 0, 0.7), b, renders(0.7));
  fx = {};
  verifier.decide(check, lease, b, v, now, fx);
  ASSERT_TRUE(verifier.quarantined(a));
  ASSERT_FALSE(fx.rows.empty());
  for (const RowEnd& row : fx.rows) EXPECT_NE(jobs.find_sequence(row.id), nullptr) << row.id << " has no row";
  const std::string error = job_status(jobs, leases, s.id(), false, now).error();
  EXPECT_TRUE(has(error, "quarantined")) << error;
}

// ... and so does a frame that had left memory (JobTable::let_go) when the liar was found.
TEST_F(VerifierTest, AFrameThatLeftMemoryWithALiarsTilesFlagsItsSequence) {
  Sequence& s = add_sequence({1, 2});
  Job& frame = start_frame(s);
  frame.merged_by[a] = {0, 1};
  frame.merged_by[b] = {2};
  testing::merge_passes(frame.plan, uint32_t(frame.plan.passes().size()));
  lifecycle.finish_if_done(frame, now, fx);
  frame.end_recorded = true;
  frame.compact();
  ASSERT_TRUE(jobs.let_go(frame));
  fx = {};
  verifier.quarantine(a, "a test", now, fx);
  const std::string error = job_status(jobs, leases, s.id(), false, now).error();
  EXPECT_TRUE(has(error, "2 tiles of finished frames hold results of worker")) << error;
  EXPECT_EQ(s.left_merged_by.count(a), 0u);
  EXPECT_EQ(s.left_merged_by.at(b), 1u);
}

TEST_F(VerifierTest, ACheckerTheRefereeDisagreesWithIsTheOneQuarantined) {
  const uint64_t check = merged_and_picked(*job, a);
  const uint64_t lease = lease_check(b);
  const Verifier::Verdict v = Verifier::judge(*verifier.pending(check, lease), digest(0, 0, 0.7), b, renders(0.5));
  EXPECT_EQ(v.liars, std::vector<uint64_t>{b});
  EXPECT_FALSE(verifier.decide(check, lease, b, v, now, fx));  // its result does not count
  EXPECT_TRUE(verifier.quarantined(b));
  EXPECT_FALSE(verifier.quarantined(a));
  EXPECT_EQ(job->plan.progress(0).passes_done, 1u);  // a's merge stands
}

TEST_F(VerifierTest, WhenTheRefereeCannotRenderNobodyIsQuarantined) {
  const uint64_t check = merged_and_picked(*job, a);
  const uint64_t lease = lease_check(b);
  const Referee broken = [](const v1::Task&) -> std::vector<PixelSums> { throw std::runtime_error("no scene"); };
  const Verifier::Verdict v = Verifier::judge(*verifier.pending(check, lease), digest(0, 0, 0.7), b, broken);
  EXPECT_FALSE(v.same);
  EXPECT_TRUE(v.liars.empty());
  verifier.decide(check, lease, b, v, now, fx);
  EXPECT_EQ(counters.check_mismatches, 1u);
  EXPECT_EQ(counters.workers_quarantined, 0u);
  EXPECT_EQ(checks.find(check), nullptr);
}

TEST_F(VerifierTest, ACheckNoOtherWorkerCanTakeIsSkipped) {
  testing::merge_passes(job->plan, testing::kPasses);
  Lease l{job->id(), 0, 0, a, now + 5, std::make_shared<const v1::Task>()};
  verifier.issue(*job, l, a, 1234, now);
  verifier.skip_stale(now, fx);
  EXPECT_EQ(checks.all().size(), 1u);  // b could take it
  workers.remove(b);
  verifier.skip_stale(now, fx);
  EXPECT_TRUE(checks.all().empty());
  EXPECT_EQ(counters.checks_skipped, 1u);
  EXPECT_EQ(job->pending_checks, 0u);
  EXPECT_EQ(job->state(), v1::JobStatus::DONE);  // it waited only for the check
  ASSERT_EQ(fx.writes.size(), 1u);
  EXPECT_TRUE(snapshotter.next(*job, now).ended);
}

TEST_F(VerifierTest, ACheckWaitingForMoreThanTwoLeasePeriodsIsSkipped) {
  const uint64_t check = merged_and_picked(*job, a);
  const double since = checks.find(check)->since;
  verifier.skip_stale(since + 2 * options.lease_seconds, fx);
  EXPECT_NE(checks.find(check), nullptr);
  verifier.skip_stale(since + 2 * options.lease_seconds + 0.001, fx);
  EXPECT_EQ(checks.find(check), nullptr);
  EXPECT_EQ(counters.checks_skipped, 1u);
}

TEST_F(VerifierTest, ALeasedCheckIsNeverSkipped) {
  const uint64_t check = merged_and_picked(*job, a);
  lease_check(b);
  workers.remove(b);  // even with nobody else left: its lease expires first, then it waits again
  verifier.skip_stale(now + 100 * options.lease_seconds, fx);
  EXPECT_NE(checks.find(check), nullptr);
}

// Probation counts results that show light. A black tile's sums are zeros whatever scale a
// liar applies, so such a result passes its check and proves nothing: it is checked, and
// the worker's probation gets the task back (a liar whose first tasks were all black would
// otherwise pass probation and be caught only by the fraction, maybe after its job ended).
class ProbationTest : public testing::PartsTest {
 protected:
  ProbationTest() : PartsTest(rarely_checked()) {}
  static CoordinatorOptions rarely_checked() {
    CoordinatorOptions o = testing::parts_options();
    o.verify_fraction = 1e-12;  // only probation picks
    return o;
  }
  std::shared_ptr<Job> job = add_still();
  uint64_t fresh = add_worker(1, "fresh"), other = add_worker(1, "other");  // (checks need another worker)
  // The worker's next task as GetTask hands it out, returned black or lit; whether a check
  // was issued for it.
  bool returned(bool black) {
    const v1::GetTaskResponse r = dispatcher.get_task(fresh, 1, 0, now, fx);
    EXPECT_EQ(r.tasks_size(), 1);
    v1::TaskResult res = result(r.tasks(0).task_id());
    if (black) {
      const Lease* l = leases.known(r.tasks(0).task_id());
      std::vector<PixelSums> sums = plausible_sums(job->plan, l->tile, l->pass);
      for (PixelSums& p : sums) p = PixelSums{0, 0, 0, 0, p.n};
      res.set_sums_zstd(encode_sums(sums));
    }
    const size_t before = checks.all().size();
    EXPECT_TRUE(submit(res).accepted());
    return checks.all().size() == before + 1;
  }
};

TEST_F(ProbationTest, ABlackResultIsCheckedButDoesNotCountTowardProbation) {
  worker(fresh).probation = 2;
  EXPECT_TRUE(returned(true));
  EXPECT_EQ(worker(fresh).probation, 2u);  // given back
  EXPECT_TRUE(returned(false));
  EXPECT_EQ(worker(fresh).probation, 1u);
  EXPECT_TRUE(returned(true));
  EXPECT_EQ(worker(fresh).probation, 1u);
  EXPECT_TRUE(returned(false));
  EXPECT_EQ(worker(fresh).probation, 0u);
  EXPECT_FALSE(returned(false));  // past probation: the fraction decides
  EXPECT_EQ(counters.checks_issued, 4u);
}

}  // namespace
}  // namespace tessera
