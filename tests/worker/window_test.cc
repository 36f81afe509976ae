// A worker's window of work in flight (worker/lookahead.h) and its task queue
// (worker/task_queue.h), with numbers: the rule, the measured speed and round trip that
// size it, the bounds on it and the order tasks are rendered in.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <vector>

#include "worker/lookahead.h"
#include "worker/task_queue.h"

namespace tessera {
namespace {

using worker::Held;
using worker::LeaseRequest;
using worker::Lookahead;
using worker::QueueLoad;
using worker::TaskQueue;

// The lookahead rule with numbers: 2 threads at 1000 samples per thread-second keep 0.5 s
// of work, 1000 samples, refilled below half of it.
TEST(Lookahead, RefillsBelowHalfTheLookaheadUpToAllOfIt) {
  const Lookahead l{2, 0.5};
  const size_t bound = 8;  // leases it may hold
  EXPECT_TRUE(l.wants_more({0, 0, 0, 0, 0, bound}));
  EXPECT_EQ(l.request({0, 0, 0, 0, 0, bound}).max_tasks, 2u);  // unmeasured: two tasks
  EXPECT_EQ(l.request({0, 0, 0, 0, 0, bound}).max_samples, 0u);
  EXPECT_FALSE(l.wants_more({2, 4, 5000, 0, 0, bound}));    // two rows a thread queued, speed unknown
  EXPECT_TRUE(l.wants_more({2, 3, 5000, 1000, 0, bound}));  // threads about to run dry
  EXPECT_TRUE(l.wants_more({2, 4, 499, 1000, 0, bound}));
  EXPECT_FALSE(l.wants_more({2, 4, 500, 1000, 0, bound}));
  const LeaseRequest r = l.request({3, 4, 400, 1000, 0, bound});
  EXPECT_EQ(r.max_tasks, 5u);
  EXPECT_EQ(r.max_samples, 600u);
  EXPECT_FALSE(l.wants_more({8, 0, 0, 1000, 0, bound}));  // every lease it may hold
}

// The window follows the link: 2 threads at 1000 samples per thread-second with a 0.3 s
// lookahead keep 600 samples next door and 2 x 1000 x (0.3 + 2 x 0.15) = 1200 behind a
// 150 ms round trip, refilled below half the lookahead plus two round trips (900).
TEST(Lookahead, AFarCoordinatorGetsTheBandwidthDelayProductInFlight) {
  const Lookahead l{2, 0.3};
  const QueueLoad near{2, 4, 299, 1000, 0, 4096}, far{2, 4, 899, 1000, 0.15, 4096};
  EXPECT_DOUBLE_EQ(l.window_samples(near), 600);
  EXPECT_DOUBLE_EQ(l.window_samples(far), 1200);
  EXPECT_TRUE(l.wants_more(near));
  EXPECT_TRUE(l.wants_more(far));
  EXPECT_FALSE(l.wants_more({2, 4, 300, 1000, 0, 4096}));
  EXPECT_FALSE(l.wants_more({2, 4, 900, 1000, 0.15, 4096}));
  EXPECT_DOUBLE_EQ(l.refill_samples(far), 3 * 2 * 1000 * 0.15);  // a round trip of tiles 3x faster
  EXPECT_EQ(l.request(near).max_samples, 301u);
  EXPECT_EQ(l.request(far).max_samples, 301u);
  EXPECT_EQ(l.request(far).max_tasks, 4094u);  // room up to the coordinator's bound
  EXPECT_FALSE(l.wants_more({4096, 0, 0, 1000, 0.15, 4096}));
}

// The round trip is smoothed as TCP smooths it (gain 1/8), but a longer one is followed at
// once by half the difference, so the threads do not run dry while the average catches up.
// A far worker takes runs of a tile's passes, enough that its threads render a task for a
// round trip: 2 threads at 2.7 M samples per thread-second, passes of 16384 samples (a
// 32x32 tile at 16 samples a pixel, 3 ms of the worker's time).
TEST(Lookahead, AFarWorkerAsksForRunsThatRenderForARoundTrip) {
  const Lookahead l{2, 0.3};
  QueueLoad load{0, 0, 0, 2.7e6, 0.150, 64, 1, 16384};
  EXPECT_EQ(l.chain_passes(load), 50u);  // ceil(0.150 / 0.00303)
  EXPECT_EQ(l.request(load).max_passes, 50u);
  load.round_trip = 0.020;
  EXPECT_EQ(l.chain_passes(load), 7u);
  load.round_trip = 0.002;  // a LAN: one pass a task, the progressive image stays fine
  EXPECT_EQ(l.chain_passes(load), 1u);
  load.passes_per_task = 3;  // the link's budget asks for more (upload_budget.h)
  EXPECT_EQ(l.request(load).max_passes, 3u);
  load.round_trip = 5;  // never more than the coordinator's bound
  EXPECT_EQ(l.chain_passes(load), Lookahead::kMaxPasses);
  load.pass_samples = 0;  // nothing measured yet
  EXPECT_EQ(l.chain_passes(load), 1u);
  load.pass_samples = 16384;
  load.passes_per_task = 1;
  load.passes_fixed = true;  // --passes-per-task 1: one pass a task however far
  EXPECT_EQ(l.request(load).max_passes, 1u);
}

TEST(TaskQueue, SmoothsTheRoundTripAndFollowsALongerOneQuickly) {
  TaskQueue q(Lookahead{2, 0.3});
  EXPECT_EQ(q.load().round_trip, 0);  // unknown until measured
  q.note_round_trip(0.1);
  EXPECT_DOUBLE_EQ(q.load().round_trip, 0.1);
  q.note_round_trip(0.3);
  EXPECT_DOUBLE_EQ(q.load().round_trip, 0.2);
  q.note_round_trip(0.04);
  EXPECT_DOUBLE_EQ(q.load().round_trip, 0.18);
  q.note_round_trip(-1);  // a clock step: no negative round trip
  EXPECT_DOUBLE_EQ(q.load().round_trip, 0.1575);
}

TEST(TaskQueue, TheCoordinatorsBoundOrAnOwnLowerCapLimitsTheLeases) {
  TaskQueue q(Lookahead{2, 0.3});
  EXPECT_EQ(q.load().max_leases, 64u);  // until registered
  q.set_max_leases(4096, 0);
  EXPECT_EQ(q.load().max_leases, 4096u);
  q.set_max_leases(4096, 100);
  EXPECT_EQ(q.load().max_leases, 100u);
  q.set_max_leases(50, 100);
  EXPECT_EQ(q.load().max_leases, 50u);
}

// A window may hold several jobs' tasks: the higher priority's are rendered first, but a
// task already begun is finished first.
TEST(TaskQueue, HigherPriorityTasksAreRenderedFirst) {
  TaskQueue q(Lookahead{1, 0.3});
  auto task = [](uint64_t id, int32_t priority) {
    auto h = std::make_shared<Held>();
    h->task.set_task_id(id);
    h->task.set_priority(priority);
    h->task.set_sample_end(1);
    h->rect = {0, 0, 2, 2};
    h->sums.resize(4);
    return h;
  };
  q.add(task(1, 0));
  ASSERT_EQ(q.next_row()->task->task.task_id(), 1u);  // task 1 begun
  q.add(task(2, 0));
  q.add(task(3, 5));
  q.add(task(4, -1));
  q.add(task(5, 5));
  std::vector<uint64_t> order;
  for (int rows = 0; rows < 9; ++rows) {
    const auto r = q.next_row();
    ASSERT_TRUE(r);
    if (order.empty() || order.back() != r->task->task.task_id()) order.push_back(r->task->task.task_id());
  }
  EXPECT_EQ(order, (std::vector<uint64_t>{1, 3, 5, 2, 4}));
  q.stop();
}

// Found by audit: a task was heartbeaten only once prepared (its scene fetched, loaded and
// built), so a preparation longer than the lease let it expire, and a failure after that
// went uncounted. It is heartbeaten from its lease on; one the coordinator refuses
// meanwhile is not queued; a stop gives it back with the held ones.
TEST(TaskQueue, ATaskBeingPreparedIsHeartbeatenAndCanBeRefused) {
  TaskQueue q(Lookahead{1, 0.3});
  auto task = [](uint64_t id) {
    auto h = std::make_shared<Held>();
    h->task.set_task_id(id);
    h->task.set_sample_end(1);
    h->rect = {0, 0, 2, 2};
    h->sums.resize(4);
    return h;
  };
  q.preparing(1);
  q.preparing(2);
  q.preparing(3);
  EXPECT_EQ(q.held_ids(), (std::vector<uint64_t>{1, 2, 3}));
  EXPECT_TRUE(q.add(task(1)));
  q.drop_unfinished({2});  // the heartbeat's answer: refused
  EXPECT_FALSE(q.add(task(2)));
  EXPECT_EQ(q.held_ids(), (std::vector<uint64_t>{1, 3}));
  q.not_prepared(3);  // its preparation failed: released
  EXPECT_EQ(q.held_ids(), (std::vector<uint64_t>{1}));
  q.preparing(4);
  std::vector<uint64_t> back = q.take_held();
  std::sort(back.begin(), back.end());
  EXPECT_EQ(back, (std::vector<uint64_t>{1, 4}));
  EXPECT_FALSE(q.add(task(4)));  // given back: not rendered after
  q.stop();
}

// The queue measures the speed from the rows' render times, which sizes the next request.
TEST(TaskQueue, MeasuresTheSpeedThatSizesTheNextRequest) {
  TaskQueue q(Lookahead{2, 0.5});
  q.set_max_leases(8, 0);
  auto h = std::make_shared<Held>();
  h->task.set_task_id(1);
  h->task.set_sample_begin(0);
  h->task.set_sample_end(100);
  h->rect = {0, 0, 4, 2};
  h->sums.resize(8);
  q.add(h);
  EXPECT_EQ(q.load().queued_rows, 2u);
  EXPECT_EQ(q.load().queued_samples, 800);
  const auto r0 = q.next_row(), r1 = q.next_row();
  ASSERT_TRUE(r0 && r1);
  EXPECT_EQ(r1->row, 1);
  TileStats row;
  row.samples = 400;
  q.row_done(*r0, std::vector<PixelSums>(4), row, 1.0, 1.015625);  // 1/64 s each, on two threads
  q.row_done(*r1, std::vector<PixelSums>(4), row, 1.0, 1.015625);
  EXPECT_EQ(q.load().samples_per_thread_second, 25600);  // 800 samples in 1/32 thread-seconds
  const std::optional<LeaseRequest> next = q.wait_for_room(std::chrono::milliseconds(0));
  ASSERT_TRUE(next);
  EXPECT_EQ(next->max_tasks, 7u);        // the finished task is held until sent
  EXPECT_EQ(next->max_samples, 25600u);  // 2 threads x 25600 x 0.5 s
  const TaskQueue::Batch b = q.take_finished(std::chrono::milliseconds(0));
  ASSERT_EQ(b.tasks.size(), 1u);
  EXPECT_EQ(b.busy_thread_seconds, 0.03125);
  q.sent(b, true);
  EXPECT_EQ(q.tasks_done(), 1u);
  EXPECT_FALSE(q.holds_tasks());
  q.stop();
  EXPECT_FALSE(q.next_row());
}

}  // namespace
}  // namespace tessera
