// ResultIntake: results screened (known task, from its lease's holder, still wanted),
// decoded and checked outside the lock, then merged: the first copy of a (tile, pass) wins.
#include "server/result_intake.h"

#include <gtest/gtest.h>
#include <zstd.h>

#include <cmath>
#include <limits>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::kTiles;

class ResultIntakeTest : public testing::OneJobTest {
 protected:
  // The ack of a result that was refused: neither accepted nor a duplicate.
  static bool rejected(const v1::ResultAck& ack) { return !ack.accepted() && !ack.duplicate(); }
};

TEST_F(ResultIntakeTest, TheHoldersResultIsMergedAndItsLeaseEnds) {
  const uint64_t t = lease_next(*job, a);
  const v1::ResultAck ack = submit(result(t));
  EXPECT_TRUE(ack.accepted());
  EXPECT_EQ(job->plan.progress(0).passes_done, 1u);
  EXPECT_EQ(job->plan.samples_merged(), testing::kFirstPassSamples);
  EXPECT_EQ(counters.results_merged, 1u);
  EXPECT_EQ(counters.samples_merged, testing::kFirstPassSamples);
  EXPECT_EQ(leases.live(t), nullptr);
  EXPECT_EQ(job->tile_lease[0], 0u);
  EXPECT_EQ(worker(a).leases, 0u);
  EXPECT_EQ(worker(a).tasks_done, 1u);
  EXPECT_TRUE(fx.changed);
}

// Found by review: a worker's speed was its claimed samples over its claimed seconds, so one
// result saying UINT64_MAX samples in 1e-300 s made it, the farm's thread speed and the
// remaining-work signal infinite for good. The speed counts the samples merged, over at
// least kMinTaskSeconds; a time that is no time feeds neither the speed nor the histogram.
TEST_F(ResultIntakeTest, AWorkersSpeedIsBoundedByWhatItMerged) {
  v1::TaskResult r = result(lease_next(*job, a));
  r.set_samples(std::numeric_limits<uint64_t>::max());
  r.set_render_seconds(1e-300);
  ASSERT_TRUE(submit(r).accepted());
  EXPECT_EQ(worker(a).samples_per_second, testing::kFirstPassSamples / WorkerRegistry::kMinTaskSeconds);
  EXPECT_TRUE(std::isfinite(workers.thread_speed()));
  for (const double bad : {std::numeric_limits<double>::infinity(), std::nan(""), -1.0}) {
    v1::TaskResult next = result(lease_next(*job, a));
    next.set_render_seconds(bad);
    next.set_thread_seconds(std::numeric_limits<double>::infinity());
    ASSERT_TRUE(submit(next).accepted());
  }
  EXPECT_EQ(worker(a).samples_per_second, testing::kFirstPassSamples / WorkerRegistry::kMinTaskSeconds);
  EXPECT_TRUE(std::isfinite(worker(a).thread_seconds));
  EXPECT_TRUE(std::isfinite(counters.task_seconds.sum));
  EXPECT_EQ(counters.task_seconds.count, 1u);
}

TEST_F(ResultIntakeTest, AStrangersResultIsRejectedAndCounted) {
  const uint64_t t = lease_next(*job, a);
  v1::TaskResult r = result(t);
  r.set_worker_id(b);
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(counters.results_rejected, 1u);
  EXPECT_EQ(job->plan.merges(), 0u);
  EXPECT_NE(leases.live(t), nullptr);  // a's lease stands
}

TEST_F(ResultIntakeTest, AResultForATaskNeverIssuedIsRejectedAndCounted) {
  const uint64_t t = lease_next(*job, a);
  v1::TaskResult r = result(t);
  r.set_task_id(t + 1000);
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(counters.results_rejected, 1u);
  EXPECT_EQ(job->plan.merges(), 0u);
}

TEST_F(ResultIntakeTest, AQuarantinedWorkersResultIsRejectedAndCounted) {
  const uint64_t t = lease_next(*job, a);
  checks.quarantine(a);
  EXPECT_TRUE(rejected(submit(result(t))));
  EXPECT_EQ(counters.results_rejected, 1u);
  EXPECT_EQ(job->plan.merges(), 0u);
}

TEST_F(ResultIntakeTest, ASecondCopyIsAckedAsADuplicate) {
  const v1::TaskResult r = result(lease_next(*job, a));
  ASSERT_TRUE(submit(r).accepted());
  const v1::ResultAck again = submit(r);
  EXPECT_FALSE(again.accepted());
  EXPECT_TRUE(again.duplicate());
  EXPECT_EQ(counters.results_duplicate, 1u);
  EXPECT_EQ(counters.results_merged, 1u);
  EXPECT_EQ(job->plan.merges(), 1u);
}

TEST_F(ResultIntakeTest, TwoCopiesInOneBatchMergeOnce) {
  const v1::TaskResult r = result(lease_next(*job, a));
  const std::vector<v1::ResultAck> acks = submit(std::vector<v1::TaskResult>{r, r});
  EXPECT_TRUE(acks[0].accepted());
  EXPECT_TRUE(acks[1].duplicate());  // looked at again when merging
  EXPECT_EQ(job->plan.merges(), 1u);
}

// Found by audit: every copy of a result in one batch was decoded (each held until the merge)
// before the second was found a duplicate: 12,000 copies of a 25-byte result took the
// coordinator from 28 MB to 1.9 GB. Copies after the first are duplicates before decoding.
TEST_F(ResultIntakeTest, CopiesInOneBatchAreDuplicatesBeforeTheyAreDecoded) {
  const v1::TaskResult r = result(lease_next(*job, a));
  const std::vector<const v1::TaskResult*> batch(1000, &r);
  const ResultIntake::Batch b = intake.screen(batch);
  EXPECT_EQ(b.incoming.size(), 1u);
  EXPECT_TRUE(b.acks[1].duplicate() && b.acks[999].duplicate());
  EXPECT_EQ(counters.results_duplicate, 999u);
}

// Found by audit: a batch's results were all decoded before any merged, so 20 small results
// whose splats each decode to 41 MB held 820 MB at once. A batch is decoded and merged a slice
// at a time, each slice at most kDecodedBytesPerSlice decoded (one result at least).
TEST_F(ResultIntakeTest, ABatchIsDecodedInSlicesOfBoundedBytes) {
  ResultIntake::Batch b;
  const uint64_t declared = 50 << 20;  // each result's splats, as their zstd frame declares
  const std::string zeros(declared, '\0');
  std::string splats(ZSTD_compressBound(declared), '\0');
  splats.resize(ZSTD_compress(splats.data(), splats.size(), zeros.data(), zeros.size(), 1));
  std::vector<v1::TaskResult> results(5);
  for (size_t i = 0; i < results.size(); ++i) {
    results[i].set_splats_zstd(splats);
    b.results.push_back(&results[i]);
    ResultIntake::Incoming in;
    in.index = i;
    in.pixels = 16 * 16;
    b.incoming.push_back(in);
  }
  const uint64_t each = ResultIntake::decoded_bytes(b, b.incoming[0]);
  EXPECT_EQ(each, declared + 16 * 16 * sizeof(PixelSums));
  ASSERT_LT(2 * each, ResultIntake::kDecodedBytesPerSlice);
  ASSERT_GT(3 * each, ResultIntake::kDecodedBytesPerSlice);
  EXPECT_EQ(ResultIntake::slice_end(b, 0), 2u);
  EXPECT_EQ(ResultIntake::slice_end(b, 2), 4u);
  EXPECT_EQ(ResultIntake::slice_end(b, 4), 5u);
  // One result past the bound alone is a slice of its own.
  b.incoming[0].pixels = size_t(ResultIntake::kDecodedBytesPerSlice / sizeof(PixelSums));
  EXPECT_EQ(ResultIntake::slice_end(b, 0), 1u);
}

TEST_F(ResultIntakeTest, SumsOfTheWrongSizeAreRejected) {
  const uint64_t t = lease_next(*job, a);
  v1::TaskResult r = result(t);
  r.set_raw_size(r.raw_size() - uint32_t(kBytesPerPixel));
  EXPECT_TRUE(rejected(submit(r)));
  r = result(t);  // a whole tile's sums, but for another tile's size
  r.set_sums_zstd(encode_sums(std::vector<PixelSums>(64)));
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(counters.results_rejected, 2u);
  EXPECT_EQ(job->plan.merges(), 0u);
  EXPECT_TRUE(submit(result(t)).accepted());  // the lease still waits for a good one
}

// A result its task's holder sent that does not decode is that worker's failure of the
// task, said in the ack and a task.failed event, once a lease; once two workers failed, the
// job fails naming why (before, a farm whose workers all sent such results, a version skew
// say, went round for ever in silence).
TEST_F(ResultIntakeTest, AResultThatDoesNotDecodeFailsTheTaskOnItsWorker) {
  const uint64_t t = lease_next(*job, a);
  v1::TaskResult r = result(t);
  r.set_raw_size(r.raw_size() - uint32_t(kBytesPerPixel));
  const v1::ResultAck ack = submit(r);
  EXPECT_TRUE(rejected(ack));
  EXPECT_EQ(ack.refused(), "result refused: raw size does not match the tile");
  EXPECT_EQ(counters.tasks_failed, 1u);
  ASSERT_FALSE(fx.events.empty());
  EXPECT_EQ(fx.events.back().kind, "task.failed");
  EXPECT_EQ(fx.events.back().worker, worker(a).name);
  EXPECT_EQ(fx.events.back().detail, ack.refused());
  EXPECT_TRUE(job->live());  // maybe that worker's trouble
  const size_t events = fx.events.size();
  EXPECT_TRUE(rejected(submit(r)));                                         // again: one failure, one event a lease
  worker_lifecycle.release(a, t, "and given back with an error", now, fx);  // nor by a release
  EXPECT_EQ(counters.tasks_failed, 1u);
  EXPECT_EQ(fx.events.size(), events);
  EXPECT_TRUE(submit(result(t)).accepted());  // the lease still waits for a good one

  const uint64_t u = lease_next(*job, b);
  v1::TaskResult nan = result(u, std::nan(""));
  EXPECT_FALSE(submit(nan).refused().empty());
  EXPECT_FALSE(job->live());
  EXPECT_NE(job->error.find("tasks failed on 2 workers: result refused: "), std::string::npos) << job->error;
}

// A frame's results carry splats exactly when it traces light paths (its --light-tracer,
// resolved at submit): splats for a frame without, or none for a frame with, are refused.
TEST_F(ResultIntakeTest, SplatsComeExactlyFromFramesThatTraceLightPaths) {
  SplatRecord record;
  record.paths = 4;
  record.entries.push_back({7, {1, 2, 3, 4}});
  const uint64_t t = lease_next(*job, a);
  v1::TaskResult r = result(t);
  r.set_splats_zstd(encode_splats({record}));
  EXPECT_TRUE(rejected(submit(r)));  // this frame traces none
  EXPECT_FALSE(job->splats.any());
  EXPECT_TRUE(submit(result(t)).accepted());

  RenderSettings on = testing::small_settings();
  on.light_tracer = RenderSettings::LightTracer::kOn;
  const std::shared_ptr<Job> traced = add_still(on);
  const uint64_t u = lease_next(*traced, a);
  EXPECT_TRUE(rejected(submit(result(u))));  // no splats
  v1::TaskResult two = result(u);
  two.set_splats_zstd(encode_splats({record, record}));  // a record too many for one pass
  EXPECT_TRUE(rejected(submit(two)));
  EXPECT_EQ(counters.results_rejected, 3u);
  v1::TaskResult good = result(u);
  good.set_splats_zstd(encode_splats({record}));
  EXPECT_TRUE(submit(good).accepted());
  ASSERT_TRUE(traced->splats.any());
  EXPECT_EQ(traced->splats.film()->paths(), 4u);
  EXPECT_EQ(traced->splats.film()->at(7, 0).rgb[1], 2);
  EXPECT_EQ(traced->splats.frontier(traced->plan.tiles().size() - 1), 0u);  // only the leased tile moved
}

// The most light paths a task's record may declare: its tile's pixels times the most a
// pixel traces in the pass, which is two for a pass straddling two blocks of 4 samples.
TEST_F(ResultIntakeTest, ARecordsLightPathsAreBoundedByItsPass) {
  RenderSettings s = testing::small_settings();
  s.light_tracer = RenderSettings::LightTracer::kOn;
  const Rect tile{0, 0, 3, 5};
  EXPECT_EQ(ResultIntake::splat_limits(s, tile, {{0, 4}}).max_paths, 15u);
  EXPECT_EQ(ResultIntake::splat_limits(s, tile, {{3, 5}}).max_paths, 30u);
  EXPECT_EQ(ResultIntake::splat_limits(s, tile, {{0, 1}}).max_paths, 15u);
  EXPECT_EQ(ResultIntake::splat_limits(s, tile, {{0, 16}, {16, 19}}).max_paths, 60u);
  EXPECT_EQ(ResultIntake::splat_limits(s, tile, {{0, 16}, {16, 19}}).records, 2u);
}

// A run of many passes of a large tile can carry more splats than a result may (the
// decoder's cap): leased again whole it would fail again, for ever. The job's runs are
// halved and the run is ready again at once.
TEST_F(ResultIntakeTest, SplatsPastTheCapShortenTheJobsRuns) {
  RenderSettings on = testing::small_settings();
  on.light_tracer = RenderSettings::LightTracer::kOn;
  const std::shared_ptr<Job> traced = add_still(on);
  const std::optional<TileTask> run = traced->plan.take(2);
  ASSERT_TRUE(run);
  ASSERT_EQ(run->pass_count, 2u);
  const size_t ready = traced->plan.ready();
  const uint64_t t = leasing.grant(*traced, *run, worker(a), now);
  v1::TaskResult r = result(t);
  // A zstd frame header alone, declaring 2^40 bytes: what a too-long run would declare.
  std::string header = {'\x28', '\xb5', '\x2f', '\xfd', '\xe0'};
  for (int i = 0; i < 8; ++i) header += char(i == 5 ? 1 : 0);
  r.set_splats_zstd(header);
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(traced->max_run, 1u);
  EXPECT_EQ(leases.live(t), nullptr);
  EXPECT_EQ(traced->plan.ready(), ready + 1);  // the run's tile is ready again
  EXPECT_EQ(traced->plan.take(traced->max_run)->pass_count, 1u);
}

TEST_F(ResultIntakeTest, SumsThatAreNotZstdAreRejected) {
  v1::TaskResult r = result(lease_next(*job, a));
  r.set_sums_zstd("not zstd at all");
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(counters.results_rejected, 1u);
}

TEST_F(ResultIntakeTest, ImplausibleSumsAreRejected) {
  const uint64_t t = lease_next(*job, a);
  const FramePlan& plan = job->plan;
  auto with = [&](auto&& change) {
    std::vector<PixelSums> sums = testing::plausible_sums(plan, 0, 0);
    change(sums[7]);
    v1::TaskResult r = result(t);
    r.set_sums_zstd(encode_sums(sums));
    return submit(r);
  };
  EXPECT_TRUE(rejected(with([](PixelSums& p) { p.g = -1; })));    // radiance is never negative
  EXPECT_TRUE(rejected(with([](PixelSums& p) { ++p.n; })));       // more samples than the pass has
  EXPECT_TRUE(rejected(with([](PixelSums& p) { p.lum2 = 0; })));  // (sum l)^2 > n sum l^2
  EXPECT_TRUE(rejected(with([](PixelSums& p) { p.b = std::numeric_limits<double>::infinity(); })));
  EXPECT_EQ(counters.results_rejected, 4u);
  EXPECT_EQ(job->plan.merges(), 0u);
  // A pixel whose every sample was dropped (NaN or infinite radiance) is empty, and fine.
  EXPECT_TRUE(with([](PixelSums& p) { p = PixelSums{}; }).accepted());
}

TEST_F(ResultIntakeTest, TheFirstCopyWinsAndEndsTheOtherLease) {
  const uint64_t late = lease_next(*job, a);
  now += options.lease_seconds + 1;
  ASSERT_EQ(leasing.expire(now), 1u);  // a is slow: tile 0 goes to b
  const uint64_t again = lease_next(*job, b);
  ASSERT_EQ(leases.live(again)->tile, 0u);
  EXPECT_TRUE(submit(result(late)).accepted());  // the bits are the same, whoever sends them
  EXPECT_EQ(leases.live(again), nullptr);
  EXPECT_EQ(worker(b).leases, 0u);
  EXPECT_TRUE(submit(result(again)).duplicate());
  EXPECT_EQ(job->plan.merges(), 1u);
}

// Found by audit: every ended lease stayed a record, and its (tile, pass) a deque, about
// 0.9 KB together, until its job ended: a job of 2,000 tiles x 1,000 passes held 2 GB. Once
// its pass is merged a lease is known by its id alone, and a late copy is still a duplicate.
TEST_F(ResultIntakeTest, MergedPassesLeaveOnlyTheirLeasesIds) {
  const uint64_t slow = lease_next(*job, a);
  const v1::TaskResult late = result(slow);
  now += options.lease_seconds + 1;
  ASSERT_EQ(leasing.expire(now), 1u);
  EXPECT_EQ(leases.ended_count(), 1u);
  ASSERT_TRUE(submit(result(lease_next(*job, b))).accepted());
  EXPECT_EQ(leases.ended_count(), 0u);
  EXPECT_EQ(leases.known(slow), nullptr);
  const uint64_t duplicates = counters.results_duplicate, rejected = counters.results_rejected;
  EXPECT_TRUE(submit(late).duplicate());
  EXPECT_EQ(counters.results_duplicate, duplicates + 1);
  EXPECT_EQ(counters.results_rejected, rejected);
  render_all(*job, a);
  EXPECT_EQ(leases.ended_count(), 0u);
  EXPECT_FALSE(job->live());  // every pass of every tile merged
}

TEST_F(ResultIntakeTest, WhoMergedEachTileIsRecorded) {
  const uint64_t t0 = lease_next(*job, a), t1 = lease_next(*job, b), t2 = lease_next(*job, a);
  submit(std::vector<v1::TaskResult>{result(t0), result(t1), result(t2)});
  EXPECT_EQ(job->merged_by[a], (std::vector<uint32_t>{0, 2}));
  EXPECT_EQ(job->merged_by[b], (std::vector<uint32_t>{1}));
}

TEST_F(ResultIntakeTest, APickedTasksResultIssuesACheck) {
  const uint64_t t = lease_next(*job, a);
  leases.live(t)->task = std::make_shared<const v1::Task>();  // as the Dispatcher picks one
  ASSERT_TRUE(submit(result(t)).accepted());
  ASSERT_EQ(checks.all().size(), 1u);
  const Check& c = checks.all().begin()->second;
  EXPECT_EQ(c.job, job->id());
  EXPECT_EQ(c.tile, 0u);
  EXPECT_EQ(c.pass, 0u);
  EXPECT_EQ(c.first_worker, a);
  EXPECT_EQ(c.digest, sums_digest(testing::plausible_sums(job->plan, 0, 0)));
  EXPECT_EQ(c.lease, 0u);
  EXPECT_EQ(job->pending_checks, 1u);
  EXPECT_EQ(counters.checks_issued, 1u);
}

TEST_F(ResultIntakeTest, TheLastMergeEndsTheJobDoneWithItsFinalSnapshot) {
  render_all(*job, a);
  EXPECT_EQ(job->state(), v1::JobStatus::DONE);
  EXPECT_EQ(counters.results_merged, kTiles * testing::kPasses);
  EXPECT_EQ(job->plan.samples_merged(), testing::kSamples);
  ASSERT_TRUE(testing::contains(fx.writes, job));         // this caller writes its snapshots
  const SnapshotPlan last = snapshotter.next(*job, now);  // what is due now: the final ones
  EXPECT_TRUE(last.ended);
  EXPECT_EQ(last.state, v1::JobStatus::DONE);
  EXPECT_EQ(last.merges, job->plan.merges());
  EXPECT_TRUE(last.image && last.checkpoint);
}

TEST_F(ResultIntakeTest, AProgressiveSnapshotOnlyOnceItsIntervalPassed) {
  // A merge right after the submit: no frame pass is complete and the checkpoint interval
  // has not passed.
  ASSERT_TRUE(submit(result(lease_next(*job, a))).accepted());
  EXPECT_TRUE(fx.writes.empty());
  now += options.checkpoint_seconds;
  ASSERT_TRUE(submit(result(lease_next(*job, a))).accepted());
  ASSERT_EQ(fx.writes.size(), 1u);
  const SnapshotPlan p = snapshotter.next(*job, now);
  EXPECT_TRUE(p.checkpoint);
  EXPECT_FALSE(p.image);
  EXPECT_FALSE(p.ended);
}

TEST_F(ResultIntakeTest, AResultForAnEndedJobIsNotMerged) {
  const uint64_t t = lease_next(*job, a);
  const v1::TaskResult r = result(t);
  lifecycle.cancel(job->id(), "", true, now, fx);
  EXPECT_TRUE(rejected(submit(r)));
  EXPECT_EQ(counters.results_rejected, 1u);  // its lease is forgotten with the job
  EXPECT_EQ(job->plan.merges(), 0u);
}

}  // namespace
}  // namespace tessera
