// Not built: deploy/thread-safety.sh compiles it with clang to prove the check is alive.
// Each function breaks a lock rule of the coordinator (server/coordinator.h); clang's
// -Wthread-safety must refuse every one, or the check proves nothing.
#include "core/util/mutex.h"

namespace tessera {

struct Part {
  int n = 0;
  void bump() { ++n; }
};

class Wiring {
 public:
  void writes_unlocked() { part_.bump(); }
  int reads_unlocked() const { return part_.n; }
  int calls_a_locked_function_unlocked() { return needs_lock(); }
  template <typename F>
  void locked(F&& f) {
    MutexLock lock(mu_);
    f();
  }
  void unannotated_lambda() {
    locked([&] { part_.bump(); });
  }

 private:
  int needs_lock() TESSERA_REQUIRES(mu_) { return part_.n; }
  mutable Mutex mu_;
  Part part_ TESSERA_GUARDED_BY(mu_);
};

}  // namespace tessera
