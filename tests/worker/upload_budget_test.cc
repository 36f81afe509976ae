// The upload budget (worker/upload_budget.h): how many passes of a tile a worker's tasks
// hold so that its link carries its results. Stated with numbers, no network.
#include "worker/upload_budget.h"

#include <gtest/gtest.h>

#include "worker/sender.h"

namespace tessera::worker {
namespace {

// Calls as a worker of 2 threads makes them: 2.73 M samples a thread-second, 0.22 B a
// sample a pass (runs of `passes` send a pass's bytes for that many passes' samples); one
// call of `bytes` answered every `every` seconds, each taking `takes`.
void calls(UploadBudget& b, int n, double every, double takes, uint64_t bytes, double round_trip, double* t,
           uint32_t passes = 1) {
  for (int i = 0; i < n; ++i, *t += every) {
    UploadBudget::Call c;
    c.start = *t;
    c.end = *t + takes;
    c.bytes = bytes;
    c.samples = double(bytes) / 0.22 * passes;
    c.busy = c.samples / 2.73e6;
    c.single_pass_bytes = double(bytes) * passes;
    b.note(c, round_trip);
  }
}

TEST(UploadBudget, ALinkThatKeepsUpKeepsOnePassATask) {
  UploadBudget b(2, 0);
  double t = 0;
  // 150 ms away: results of 1.2 MB a second in calls of 120 kB, answered in a round trip
  // and a little.
  calls(b, 40, 0.1, 0.16, 120000, 0.15, &t);
  EXPECT_EQ(b.passes_per_task(), 1u);
  EXPECT_EQ(b.link_rate(), 0);
  // Slow answers the coordinator accounts for (its merges, ResultAcks.held_ms): not the link.
  UploadBudget busy(2, 0);
  for (int i = 0; i < 40; ++i) busy.note({i * 0.1, i * 0.1 + 0.5, 0.45, 120000, 545454, 0.2, 120000}, 0.001);
  EXPECT_EQ(busy.passes_per_task(), 1u);
}

TEST(UploadBudget, ResultsThatOutrunTheLinkAskForRunsOfPassesThatFitHalfOfIt) {
  UploadBudget b(2, 0);
  double t = 0;
  // 10 Mbit/s, 150 ms: the link carries 1.25 MB a second, so four calls of 120 kB in
  // flight are answered every 96 ms, each after 4 x 96 ms in the queue and a round trip.
  calls(b, 3, 0.096, 0.534, 120000, 0.15, &t);
  EXPECT_EQ(b.passes_per_task(), 1u);  // too few calls to judge
  calls(b, 20, 0.096, 0.534, 120000, 0.15, &t);
  EXPECT_NEAR(b.link_rate(), 1.25e6, 1e3);
  // The worker makes 5.46 M samples a second at 0.22 B: 1.2 MB/s into half of 1.25: two
  // passes a task.
  EXPECT_EQ(b.passes_per_task(), 2u);
  // Once runs make the results fit, the calls are quick again and the runs stay.
  calls(b, 40, 0.1, 0.16, 60000, 0.15, &t, 2);
  EXPECT_EQ(b.passes_per_task(), 2u);
}

TEST(UploadBudget, NeverMoreThanTheBoundAndAFixedCountStays) {
  UploadBudget b(2, 0);
  double t = 0;
  calls(b, 20, 0.36, 2, 3600, 0.15, &t);  // a link of 10 kB/s
  EXPECT_NEAR(b.link_rate(), 1e4, 1);
  EXPECT_EQ(b.passes_per_task(), UploadBudget::kMaxPasses);
  UploadBudget fixed(2, 3);  // --passes-per-task 3
  calls(fixed, 20, 0.36, 2, 3600, 0.15, &t);
  EXPECT_EQ(fixed.passes_per_task(), 3u);
  EXPECT_EQ(UploadBudget(2, 1000).passes_per_task(), UploadBudget::kMaxPasses);
}

// Found by audit: a batch's results went in one call whatever their size, and the
// coordinator refuses a call past its message limit: retried, then dropped, the job never
// finishing. They go in calls of at most max_call bytes (a larger result alone), and one no
// call can carry is set apart (released with its size).
TEST(Sender, ResultsGoInCallsOfBoundedSize) {
  const CallPlan p = plan_calls({10, 20, 30, 100, 5, 600, 1}, 50, 500);
  EXPECT_EQ(p.calls, (std::vector<std::vector<size_t>>{{0, 1}, {2}, {3}, {4, 6}}));
  EXPECT_EQ(p.too_large, (std::vector<size_t>{5}));
  EXPECT_TRUE(plan_calls({}, 50, 500).calls.empty());
  EXPECT_EQ(plan_calls({60}, 50, 500).calls, (std::vector<std::vector<size_t>>{{0}}));
}

}  // namespace
}  // namespace tessera::worker
