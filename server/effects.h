// The slow work a state change leaves for after the coordinator's lock. Nothing under the
// lock writes to disk, encodes an image or waits: each operation appends what it needs
// done to one Effects, and the coordinator carries it out once the lock is released
// (Coordinator::apply): waking the waiters, events, then images and checkpoints, database rows,
// sequence ends, frames to prepare, jobs to archive and flags for archived jobs.
#pragma once

#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "server/archive.h"
#include "server/events.h"
#include "server/snapshotter.h"

namespace tessera {

struct Effects {
  std::vector<std::shared_ptr<Job>> writes;  // jobs whose snapshot writer this operation became
  std::vector<RowEnd> rows;                  // database rows to rewrite
  std::vector<std::string> sequence_ends;    // sequences whose end to record (once it can be)
  std::vector<std::pair<std::shared_ptr<Sequence>, size_t>> prepare;  // sequences whose next frame's job to make
  std::vector<Archival> archive;                                      // ended jobs to leave memory (archive.h)
  // A worker quarantined: archived jobs holding its results are flagged in their rows (but
  // those flagged in memory).
  struct Flag {
    uint64_t worker = 0;
    std::string name;
    std::set<std::string> flagged_in_memory;
  };
  std::vector<Flag> flags;
  // Enrolled workers' names quarantined, with why: their credentials are refused (and kept so).
  std::vector<std::pair<std::string, std::string>> credentials_quarantined;
  bool changed = false;  // something waiters wait for happened
  // Events (events.h) to log and keep; `actor` is who asked for this operation (a token's
  // name), and who each event made under it did it.
  std::string actor;
  std::vector<Event> events;
  uint64_t events_seq = 0;  // their place among every operation's events (Coordinator::sequence)
  void event(std::string kind, std::string job, std::string worker, std::string detail) {
    events.push_back({0, 0, std::move(kind), std::move(job), std::move(worker), actor, std::move(detail)});
  }

  bool empty() const {
    return writes.empty() && rows.empty() && sequence_ends.empty() && prepare.empty() && archive.empty() &&
           flags.empty() && credentials_quarantined.empty() && events.empty() && !changed;
  }
};

}  // namespace tessera
