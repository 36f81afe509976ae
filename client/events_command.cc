#include "client/events_command.h"

#include <chrono>
#include <ctime>
#include <thread>

#include "client/cli_json.h"

namespace tessera {

const char* const kEventsHeader =
    "TIME                 EVENT               JOB               WORKER          WHO         DETAIL";

std::string event_row(const v1::Event& e) {
  const std::time_t when = std::time_t(e.time().seconds());
  std::tm local{};
  localtime_r(&when, &local);
  char time[32], buf[256];
  std::strftime(time, sizeof time, "%Y-%m-%d %H:%M:%S", &local);
  const auto dash = [](const std::string& s) { return s.empty() ? std::string("-") : s; };
  std::snprintf(buf, sizeof buf, "%-19s  %-18s  %-16s  %-14s  %-10s  ", time, e.kind().c_str(),
                dash(e.job_id()).c_str(), dash(e.worker()).c_str(), dash(e.who()).c_str());
  return buf + e.detail();
}

int list_events(v1::Tessera::StubInterface& stub, const EventsRequest& request, const FarmContext& c) {
  v1::ListEventsRequest req;
  req.set_job_id(request.job);
  req.set_limit(request.tail);
  v1::EventList got;
  check(stub.ListEvents(deadline(c).get(), req, &got), c);
  bool header = c.no_headers;
  auto print = [&](const v1::EventList& list) {
    for (const v1::Event& e : list.events()) {
      if (c.json) {  // one object a line while following (as kubectl's --watch -o json)
        if (request.follow) std::fprintf(c.out, "%s\n", cli_json(e).c_str());
        continue;
      }
      if (!header) std::fprintf(c.out, "%s\n", kEventsHeader);
      header = true;
      std::fprintf(c.out, "%s\n", event_row(e).c_str());
    }
    std::fflush(c.out);
  };
  if (c.json && !request.follow) {
    std::fprintf(c.out, "%s\n", cli_json(got).c_str());
    return 0;
  }
  print(got);
  uint64_t last = got.events().empty() ? 0 : got.events(got.events_size() - 1).id();
  req.set_oldest(true);  // from here on, everything after the last one seen
  req.set_limit(1000);
  for (int i = 0; request.follow && i != request.polls; ++i) {
    std::this_thread::sleep_for(std::chrono::duration<double>(request.poll_seconds));
    req.set_after(last);
    v1::EventList more;
    check(stub.ListEvents(deadline(c).get(), req, &more), c);
    print(more);
    if (!more.events().empty()) last = more.events(more.events_size() - 1).id();
  }
  return 0;
}

}  // namespace tessera
