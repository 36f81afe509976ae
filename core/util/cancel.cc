#include "core/util/cancel.h"

#include <atomic>

namespace tessera {
namespace {

thread_local const CancelScope* t_scope = nullptr;
std::atomic<bool> g_stopping{false};

}  // namespace

CancelScope::CancelScope(std::function<bool()> cancelled, double interval)
    : cancelled_(std::move(cancelled)),
      interval_(
          std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(interval))),
      outer_(t_scope) {
  t_scope = this;
}

CancelScope::~CancelScope() { t_scope = outer_; }

void throw_if_cancelled() {
  const CancelScope* s = t_scope;
  if (!s) return;
  if (g_stopping.load(std::memory_order_relaxed)) throw Cancelled("cancelled: the process is stopping");
  if (!s->cancelled_) return;
  const auto now = std::chrono::steady_clock::now();
  if (now < s->next_ask_) return;
  s->next_ask_ = now + s->interval_;
  if (s->cancelled_()) throw Cancelled("cancelled: the caller went away");
}

void stop_all_scoped_work() { g_stopping = true; }

}  // namespace tessera
