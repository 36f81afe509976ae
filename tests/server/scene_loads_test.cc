// SceneLoads: the coordinator loads at most --max-scene-loads scenes at once (each can take
// gigabytes within the loaders' budgets); the rest wait their turn, and a wait ends when
// its caller goes away.
#include "server/scene_loads.h"

#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <mutex>
#include <thread>
#include <vector>

namespace tessera {
namespace {

TEST(SceneLoads, AtMostTheBoundRunAtOnceAndTheRestWaitTheirTurn) {
  const SceneLoads loads(2);
  std::promise<void> release;
  const std::shared_future<void> released = release.get_future().share();
  std::atomic<int> started{0};
  auto hold = [&] {
    loads.in_turn([&] {
      ++started;
      released.wait();
    });
  };
  std::thread first(hold), second(hold);
  while (started < 2) std::this_thread::yield();
  std::atomic<bool> third_ran{false};
  std::thread third([&] { loads.in_turn([&] { return third_ran = true; }); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_FALSE(third_ran);  // waits its turn
  EXPECT_EQ(loads.running(), 2u);
  release.set_value();
  first.join();
  second.join();
  third.join();
  EXPECT_TRUE(third_ran);
  EXPECT_EQ(loads.running(), 0u);
  // Many at once: never more than the bound.
  std::atomic<int> now{0}, most{0}, done{0};
  std::vector<std::thread> callers;
  for (int i = 0; i < 6; ++i)
    callers.emplace_back([&] {
      loads.in_turn([&] {
        const int n = ++now;
        for (int m = most.load(); n > m && !most.compare_exchange_weak(m, n);) {
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        --now;
        return ++done;
      });
    });
  for (std::thread& t : callers) t.join();
  EXPECT_EQ(done, 6);
  EXPECT_LE(most, 2);
  EXPECT_EQ(loads.running(), 0u);
}

// A turn taken on a thread of its own and held until release().
class HeldTurn {
 public:
  explicit HeldTurn(const SceneLoads& loads)
      : thread_([this, &loads] {
          loads.in_turn([this] {
            holding_.set_value();
            release_.get_future().wait();
          });
        }) {
    holding_.get_future().wait();
  }
  ~HeldTurn() { release(); }
  void release() {
    if (!thread_.joinable()) return;
    release_.set_value();
    thread_.join();
  }

 private:
  std::promise<void> release_, holding_;
  std::thread thread_;
};

TEST(SceneLoads, AWaitEndsWhenItsCallerGoesAway) {
  const SceneLoads loads(1);
  HeldTurn holder(loads);
  {
    const CancelScope gone([] { return true; });  // its client went away
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_THROW(loads.in_turn([] { return 0; }), Cancelled);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  }
  EXPECT_EQ(loads.running(), 1u);  // the holder's, not the one that gave up
  holder.release();
  EXPECT_EQ(loads.in_turn([] { return 7; }), 7);  // its turn came back
}

// Turns went to whichever waiter woke first: a steady stream of submits could keep one
// waiting for good. They now go in the order they were asked for; one that gives up
// leaves the line.
TEST(SceneLoads, TurnsGoInTheOrderTheyWereAskedFor) {
  const SceneLoads loads(1);
  HeldTurn holder(loads);
  std::mutex mu;
  std::vector<int> order;
  std::atomic<bool> give_up{false};
  std::vector<std::thread> waiters;
  for (int i = 0; i < 6; ++i) {
    waiters.emplace_back([&, i] {
      const CancelScope gone([&, i] { return i == 2 && give_up.load(); });
      try {
        loads.in_turn([&] {
          std::lock_guard<std::mutex> lock(mu);
          order.push_back(i);
        });
      } catch (const Cancelled&) {
        std::lock_guard<std::mutex> lock(mu);
        order.push_back(-1);
      }
    });
    while (loads.waiting() < size_t(i) + 1) std::this_thread::yield();  // in line before the next asks
  }
  give_up = true;
  for (bool gone = false; !gone; std::this_thread::yield()) {  // the one that gave up has gone
    std::lock_guard<std::mutex> lock(mu);
    gone = !order.empty();
  }
  EXPECT_EQ(loads.waiting(), 5u);
  holder.release();
  for (std::thread& t : waiters) t.join();
  EXPECT_EQ(order, (std::vector<int>{-1, 0, 1, 3, 4, 5}));
  EXPECT_EQ(loads.waiting(), 0u);
  EXPECT_EQ(loads.running(), 0u);
}

TEST(SceneLoads, TheDefaultIsOneLoadPer16GiBOneToFour) {
  EXPECT_EQ(scene_load_default(uint64_t(4) << 30), 1u);
  EXPECT_EQ(scene_load_default(uint64_t(24) << 30), 1u);
  EXPECT_EQ(scene_load_default(uint64_t(128) << 30), 4u);
  EXPECT_EQ(scene_load_default(uint64_t(1) << 40), 4u);
}

}  // namespace
}  // namespace tessera
