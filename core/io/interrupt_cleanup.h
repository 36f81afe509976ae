// Files a command-line process removes when Ctrl-C (or a kill) ends it. Destructors do not
// run when a signal ends a process, so a download's or an output's half-written temporary
// file would stay behind; a process that installs the cleanup has each registered file
// removed, then ends by the same signal (its exit status says how it ended, as before).
//
// Only the command-line client installs it: the coordinator and the worker stop on a
// signal through their own shutdown paths, which run the destructors.
#pragma once

#include <string>

namespace tessera {

// Installs the handler for SIGINT, SIGTERM and SIGHUP (once; later calls do nothing).
void install_interrupt_cleanup();

// While it lives, `path` is removed if a signal above ends the process. Nothing happens
// where the cleanup is not installed. At most kInterruptCleanupSlots files are registered at
// once (more are left as before: a best effort, never an error).
class RemoveOnInterrupt {
 public:
  explicit RemoveOnInterrupt(const std::string& path);
  ~RemoveOnInterrupt();
  RemoveOnInterrupt(const RemoveOnInterrupt&) = delete;
  RemoveOnInterrupt& operator=(const RemoveOnInterrupt&) = delete;

 private:
  int slot_ = -1;
};

inline constexpr int kInterruptCleanupSlots = 32;

}  // namespace tessera
