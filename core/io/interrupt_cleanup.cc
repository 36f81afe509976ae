#include "core/io/interrupt_cleanup.h"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstring>

namespace tessera {

namespace {

// Fixed storage: the signal handler may only read memory that nothing frees under it.
struct Slot {
  std::atomic<int> state{0};  // 0 free, 1 being written or cleared, 2 holds a path
  char path[4096];
};
Slot g_slots[kInterruptCleanupSlots];
std::atomic<bool> g_installed{false};

void on_signal(int sig) {
  for (Slot& s : g_slots)
    if (s.state.load(std::memory_order_acquire) == 2) ::unlink(s.path);
  std::signal(sig, SIG_DFL);  // then end as the signal would have
  std::raise(sig);
}

}  // namespace

void install_interrupt_cleanup() {
  if (g_installed.exchange(true)) return;
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
}

RemoveOnInterrupt::RemoveOnInterrupt(const std::string& path) {
  if (!g_installed.load(std::memory_order_relaxed) || path.size() >= sizeof(Slot::path)) return;
  for (int i = 0; i < kInterruptCleanupSlots; ++i) {
    int expected = 0;
    if (!g_slots[i].state.compare_exchange_strong(expected, 1)) continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].state.store(2, std::memory_order_release);
    slot_ = i;
    return;
  }
}

RemoveOnInterrupt::~RemoveOnInterrupt() {
  if (slot_ >= 0) g_slots[slot_].state.store(0, std::memory_order_release);
}

}  // namespace tessera
