// Leasing: every lease granted and ended in one place, so that the tile's note of its
// lease, the worker's count and a check's lease never drift apart.
#include "server/leasing.h"

#include <gtest/gtest.h>

#include "core/util/invariant.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::kTiles;

class LeasingTest : public testing::OneJobTest {
 protected:
  // A check of the job's tile 0, pass 0 (as the Verifier issues it), first rendered by `first`.
  uint64_t add_check(const Job& j, uint64_t first) {
    Check c;
    c.job = j.id();
    c.task = std::make_shared<const v1::Task>();
    c.first_worker = first;
    c.since = now;
    return checks.add(std::move(c));
  }
};

TEST_F(LeasingTest, AGrantIsNotedOnTheTileTheWorkerAndTheCounters) {
  const std::optional<TileTask> t = job->plan.take();
  ASSERT_TRUE(t);
  const uint64_t id = leasing.grant(*job, *t, worker(a), now);
  EXPECT_EQ(id, uint64_t(1) << 40);  // the first of generation 1
  EXPECT_EQ(job->tile_lease[t->tile], id);
  EXPECT_EQ(worker(a).leases, 1u);
  EXPECT_EQ(counters.tasks_dispatched, 1u);
  const Lease* l = leases.live(id);
  ASSERT_NE(l, nullptr);
  EXPECT_EQ(l->job, job->id());
  EXPECT_EQ(l->tile, t->tile);
  EXPECT_EQ(l->pass, t->pass);
  EXPECT_EQ(l->worker, a);
  EXPECT_EQ(l->deadline, now + options.lease_seconds);
  EXPECT_EQ(l->check, 0u);
}

TEST_F(LeasingTest, EndedWithRequeueTheTilesPassIsReadyAgain) {
  const uint64_t id = lease_next(*job, a);
  ASSERT_EQ(job->plan.ready(), kTiles - 1);
  leasing.end(id, true, now);
  EXPECT_EQ(job->plan.ready(), kTiles);
  EXPECT_EQ(job->tile_lease[0], 0u);
  EXPECT_EQ(worker(a).leases, 0u);
  EXPECT_EQ(leases.live(id), nullptr);
  EXPECT_NE(leases.known(id), nullptr);  // a late result is still recognised
  EXPECT_EQ(job->plan.take()->tile, 0u);
}

// Leasing and releasing the same tile over and over kept every ended lease until the job
// ended: now the newest LeaseTable::kEndedPerPass of a (tile, pass) are known.
TEST_F(LeasingTest, EndedLeasesOfAPassAreBoundedTheNewestKnown) {
  std::vector<uint64_t> ids;
  for (int i = 0; i < 10; ++i) {
    ids.push_back(lease_next(*job, a));
    ASSERT_EQ(leases.live(ids.back())->tile, 0u);
    leasing.end(ids.back(), true, now);
  }
  EXPECT_EQ(leases.ended_count(), LeaseTable::kEndedPerPass);
  for (size_t i = 0; i < ids.size(); ++i)
    EXPECT_EQ(leases.known(ids[i]) != nullptr, i + LeaseTable::kEndedPerPass >= ids.size()) << i;
  // Another tile's ended lease is kept beside them; the job's end forgets them all.
  ASSERT_EQ(leases.live(lease_next(*job, a))->tile, 0u);  // (tile 0 again, held)
  const uint64_t other = lease_next(*job, a);
  ASSERT_NE(leases.live(other)->tile, 0u);
  leases.end(other);
  EXPECT_NE(leases.known(other), nullptr);
  EXPECT_EQ(leases.ended_count(), LeaseTable::kEndedPerPass + 1);
  leases.forget_job(job->id());
  EXPECT_EQ(leases.ended_count(), 0u);
}

TEST_F(LeasingTest, EndedWithoutRequeueTheTileWaitsForItsResult) {
  const uint64_t id = lease_next(*job, a);
  leasing.end(id, false, now);
  EXPECT_EQ(job->plan.ready(), kTiles - 1);
  EXPECT_EQ(job->tile_lease[0], 0u);
  EXPECT_EQ(worker(a).leases, 0u);
  EXPECT_NE(leases.known(id), nullptr);
  leasing.end(id, true, now);  // ending it again changes nothing
  EXPECT_EQ(job->plan.ready(), kTiles - 1);
}

// A backup (a tile leased a second time at the frame's end): either lease ending leaves the
// other in charge of the tile; the tile is ready again only when neither is left.
TEST_F(LeasingTest, ABackupLeaseAndTheFirstStandInForEachOther) {
  const uint64_t first = lease_next(*job, a);
  const std::optional<TileTask> again = job->plan.retake(0);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->pass, 0u);
  const uint64_t backup = leasing.grant_backup(*job, *again, worker(b), now);
  EXPECT_EQ(job->tile_lease[0], first);
  EXPECT_EQ(job->tile_backup.at(0), backup);
  EXPECT_EQ(worker(b).leases, 1u);
  EXPECT_EQ(counters.backup_leases, 1u);
  EXPECT_THROW(leasing.grant_backup(*job, *again, worker(b), now), InvariantError);  // one backup a tile
  leasing.end(first, true, now);  // the first expires: the backup goes on alone
  EXPECT_EQ(job->tile_lease[0], backup);
  EXPECT_TRUE(job->tile_backup.empty());
  EXPECT_EQ(job->plan.ready(), kTiles - 1);
  leasing.end(backup, true, now);  // now nobody has it
  EXPECT_EQ(job->tile_lease[0], 0u);
  EXPECT_EQ(job->plan.ready(), kTiles);

  const uint64_t again_first = lease_next(*job, a);
  const uint64_t again_backup = leasing.grant_backup(*job, *job->plan.retake(0), worker(b), now);
  leasing.end(again_backup, true, now);  // the backup ends: the first lease goes on
  EXPECT_EQ(job->tile_lease[0], again_first);
  EXPECT_EQ(job->plan.ready(), kTiles - 1);
  leasing.grant_backup(*job, *job->plan.retake(0), worker(b), now);
  leasing.end_tile(*job, 0, now);  // merged: both end, nothing requeued
  EXPECT_EQ(job->tile_lease[0], 0u);
  EXPECT_TRUE(job->tile_backup.empty());
  EXPECT_EQ(worker(a).leases + worker(b).leases, 0u);
  EXPECT_EQ(job->plan.ready(), kTiles - 1);
  EXPECT_FALSE(job->plan.retake(1));  // ready, not taken: nothing to back up
}

TEST_F(LeasingTest, LeasesExpireOnlyPastTheirDeadlineRequeuedAndCounted) {
  const uint64_t id = lease_next(*job, a);
  const double deadline = now + options.lease_seconds;
  EXPECT_EQ(leasing.expire(deadline), 0u);  // at the deadline it still holds
  EXPECT_NE(leases.live(id), nullptr);
  EXPECT_EQ(counters.leases_expired, 0u);
  EXPECT_EQ(leasing.expire(deadline + 0.001), 1u);
  EXPECT_EQ(leases.live(id), nullptr);
  EXPECT_EQ(counters.leases_expired, 1u);
  EXPECT_EQ(job->plan.ready(), kTiles);
  EXPECT_EQ(worker(a).leases, 0u);
}

TEST_F(LeasingTest, ARenewedLeaseExpiresLaterAndOnlyItsHolderRenewsIt) {
  const uint64_t id = lease_next(*job, a);
  EXPECT_FALSE(leasing.renew(id, b, now + 3));
  EXPECT_TRUE(leasing.renew(id, a, now + 3));
  EXPECT_EQ(leases.live(id)->deadline, now + 3 + options.lease_seconds);
  EXPECT_EQ(leasing.expire(now + options.lease_seconds + 1), 0u);
}

TEST_F(LeasingTest, EndingAWorkerRequeuesItsLeasesOnly) {
  const uint64_t a1 = lease_next(*job, a), a2 = lease_next(*job, a), b1 = lease_next(*job, b);
  EXPECT_EQ(leasing.end_worker(a, now), 2u);
  EXPECT_EQ(leases.live(a1), nullptr);
  EXPECT_EQ(leases.live(a2), nullptr);
  EXPECT_NE(leases.live(b1), nullptr);
  EXPECT_EQ(worker(a).leases, 0u);
  EXPECT_EQ(worker(b).leases, 1u);
  EXPECT_EQ(job->plan.ready(), kTiles - 1);  // b's tile is still out
}

TEST_F(LeasingTest, AnEndedJobsLeasesAndChecksEndAndAreForgotten) {
  const uint64_t t1 = lease_next(*job, a), t2 = lease_next(*job, b);
  const uint64_t check = add_check(*job, a);
  const uint64_t c1 = leasing.grant_check(check, worker(b), now);
  std::shared_ptr<Job> other = add_still();
  const uint64_t other_check = add_check(*other, a);
  const uint64_t o1 = lease_next(*other, a);
  leasing.end_job(*job, now);
  for (uint64_t id : {t1, t2, c1}) EXPECT_EQ(leases.known(id), nullptr) << id;
  EXPECT_EQ(checks.find(check), nullptr);
  EXPECT_EQ(job->tile_lease[0] + job->tile_lease[1], 0u);
  EXPECT_EQ(job->plan.ready(), kTiles - 2);  // not requeued: the job has ended
  EXPECT_EQ(worker(a).leases, 1u);           // the other job's
  EXPECT_EQ(worker(b).leases, 0u);
  EXPECT_NE(checks.find(other_check), nullptr);
  EXPECT_NE(leases.live(o1), nullptr);
}

TEST_F(LeasingTest, AChecksLeaseEndingPutsTheCheckBackToWaiting) {
  const uint64_t check = add_check(*job, a);
  const uint64_t id = leasing.grant_check(check, worker(b), now);
  EXPECT_EQ(checks.find(check)->lease, id);
  EXPECT_EQ(leases.live(id)->check, check);
  EXPECT_EQ(worker(b).leases, 1u);
  EXPECT_EQ(checks.waiting(), 0u);
  const double later = now + 7;
  leasing.end(id, true, later);
  EXPECT_EQ(checks.find(check)->lease, 0u);
  EXPECT_EQ(checks.find(check)->since, later);
  EXPECT_EQ(checks.waiting(), 1u);
  EXPECT_EQ(worker(b).leases, 0u);
  EXPECT_EQ(job->plan.ready(), kTiles);  // a check's lease is not the tile's
}

TEST_F(LeasingTest, ACheckAlreadyLeasedCannotBeGrantedAgain) {
  const uint64_t check = add_check(*job, a);
  leasing.grant_check(check, worker(b), now);
  EXPECT_THROW(leasing.grant_check(check, worker(b), now), InvariantError);
  EXPECT_THROW(leasing.grant_check(check + 1, worker(b), now), InvariantError);  // no such check
}

}  // namespace
}  // namespace tessera
