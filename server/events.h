// What happened on the farm, for operators: every job and worker event, who did it (the
// access token's name) and why (an error with its cause). Events are made under the
// coordinator's lock into Effects, then, after it, logged as one structured line each
// (logfmt: `event=job.failed job=... who=... detail="..."`) and kept in the database
// (JobStore::append_events, the newest kMaxEvents), where `tessera events` and the live
// page read them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "wire.h"

namespace tessera {

struct Event {
  uint64_t id = 0;     // given by the store, counting up
  double time = 0;     // wall seconds since 1970 (stamped when recorded)
  std::string kind;    // job.submitted, job.started, job.done, job.failed, job.cancelled,
                       // job.requeued, job.deleted, job.priority, frame.done, frame.failed,
                       // task.failed, worker.registered, worker.unregistered, worker.lost,
                       // worker.quarantined, worker.enrolled, coordinator.started
  std::string job;     // the job (a sequence's id for its frames' events); "" for a worker's
  std::string worker;  // the worker's name, when one is concerned
  std::string who;     // the token name that did it; "" for the coordinator itself
  std::string detail;  // what and why, in words
};

// The newest this many events are kept (older ones go as new ones come): flat on disk for a
// farm that runs for months.
constexpr uint64_t kMaxEvents = 100000;
// One event as a logfmt line (values with spaces or quotes quoted, as JSON strings).
std::string event_line(const Event& e);
// As the API gives them (ListEvents, /api/events).
v1::EventList to_proto(const std::vector<Event>& events);
// As /api/events gives them: {"events": [...]}, each with the proto's fields, numbers as
// numbers and the time in RFC 3339.
std::string events_json(const std::vector<Event>& events);
// A request's limit: 0 means 100, and no more than 1000 a call.
size_t event_limit(uint32_t asked);

}  // namespace tessera
