#include "worker/lease_keeper.h"

#include <algorithm>

#include "core/util/thread_pool.h"
#include "worker/clock.h"

namespace tessera::worker {

LeaseKeeper::LeaseKeeper(const Link& link, TaskQueue& queue, const std::atomic<bool>& stop)
    : link_(link), queue_(queue), stop_(stop), thread_([this] {
        set_thread_name("leases");
        keep_leases();
      }) {}

LeaseKeeper::~LeaseKeeper() { thread_.join(); }

void LeaseKeeper::heartbeat() {
  v1::HeartbeatRequest hb;
  const Link::Identity me = link_.identity();
  hb.set_worker_id(me.id);
  hb.set_worker_secret(me.secret);
  for (uint64_t id : queue_.held_ids()) hb.add_task_ids(id);
  if (hb.task_ids_size() == 0) return;
  hb.set_round_trip_us(uint32_t(std::min(queue_.load().round_trip * 1e6, 4e9)));
  v1::HeartbeatResponse hr;
  if (!link_.stub->Heartbeat(link_.context(5).get(), hb, &hr).ok()) return;
  queue_.drop_unfinished(std::vector<uint64_t>(hr.refused().begin(), hr.refused().end()));
}

void LeaseKeeper::keep_leases() {
  double due = now_seconds() + link_.heartbeat_ms / 1000.0;
  while (!queue_.stopping()) {
    if (stop_) {  // a signal: abandon unfinished work at once (renders check per pixel)
      queue_.stop();
      return;
    }
    if (now_seconds() >= due) {
      heartbeat();
      due = now_seconds() + link_.heartbeat_ms / 1000.0;
    }
    // Until the next heartbeat, looking at `stop` now and then.
    const auto until_due = std::chrono::milliseconds(int64_t((due - now_seconds()) * 1000) + 1);
    queue_.wait_stopped(std::clamp(until_due, std::chrono::milliseconds(1), kStopPoll));
  }
}

}  // namespace tessera::worker
