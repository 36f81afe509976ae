// `tessera events [JOB]`: what happened on the farm (the coordinator's events: jobs
// submitted, started, done, failed and why, cancelled and by whom, workers registered,
// lost, quarantined), as a table under a header, or --json; --follow polls for new ones
// until interrupted.
#pragma once

#include <string>

#include "client/farm_client.h"

namespace tessera {

struct EventsRequest {
  std::string job;     // only this job's (resolved from a prefix by the caller)
  uint32_t tail = 50;  // the newest this many
  bool follow = false;
  double poll_seconds = 1;  // --follow's interval
  int polls = -1;           // --follow's polls, for tests (-1: until interrupted)
};

int list_events(v1::Tessera::StubInterface& stub, const EventsRequest& request, const FarmContext& c);
// One event as a row of the table (local time to the second).
std::string event_row(const v1::Event& e);
extern const char* const kEventsHeader;

}  // namespace tessera
