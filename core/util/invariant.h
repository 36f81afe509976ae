// Broken internal invariants are bugs, and are reported as bugs: logged (critical) with
// where they broke, then thrown as InvariantError, which servers answer as an internal
// error saying so. Never for bad input: a peer's or user's mistake gets its own error.
//
//   TESSERA_INVARIANT(job != nullptr, "lease " + std::to_string(id) + " names no job");
#pragma once

#include <stdexcept>
#include <string>

namespace tessera {

class InvariantError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

// Logs and throws InvariantError("internal error (a bug): WHAT [FILE:LINE]"), FILE without
// its folders: messages reach clients, and paths of the build machine mean nothing there.
[[noreturn]] void invariant_failed(const char* condition, const char* file, int line, const std::string& what);

}  // namespace tessera

#define TESSERA_INVARIANT(condition, what)                                 \
  do {                                                                     \
    if (!(condition)) [[unlikely]]                                         \
      ::tessera::invariant_failed(#condition, __FILE__, __LINE__, (what)); \
  } while (0)
