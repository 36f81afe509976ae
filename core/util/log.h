// Logging for the long-running processes (coordinator, worker): spdlog, one line an event
// on stderr with an RFC 3339 timestamp, the program and the level. What the command-line
// client prints for a person (progress, its own errors) is output, not logging.
//
//   spdlog::warn("job {}: image: {} (kept in memory; retried)", id, why);
#pragma once

#include <spdlog/spdlog.h>

#include <string>

namespace tessera {

// Names the program in every line and sets the format and level; call first in main().
// Without it (tests), spdlog's default logger prints the same messages.
void init_logging(const std::string& program, bool verbose = false);

// An unexpected failure in a server: `what` (which can name files on its disk) goes to the
// log only, under a number the process counts up; returns the words a caller gets instead,
// "internal error #N (the coordinator's log has its details)".
std::string log_incident(const std::string& what);

}  // namespace tessera
