#include "server/events.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "server/json_text.h"

namespace tessera {
namespace {

void field(std::string& out, const char* key, const std::string& value) {
  if (value.empty()) return;
  const bool bare = value.find_first_of(" \"=\\\t\n\r") == std::string::npos &&
                    std::all_of(value.begin(), value.end(), [](unsigned char c) { return c >= 0x20 && c < 0x7f; });
  if (!out.empty()) out += ' ';
  out += key;
  out += '=';
  // Quoted as a JSON string: no value can start a line of its own or forge another field.
  out += bare ? value : nlohmann::json(value).dump(-1, ' ', true, nlohmann::json::error_handler_t::replace);
}

}  // namespace

std::string event_line(const Event& e) {
  std::string out;
  field(out, "event", e.kind);
  field(out, "job", e.job);
  field(out, "worker", e.worker);
  field(out, "who", e.who);
  field(out, "detail", e.detail);
  return out;
}

v1::EventList to_proto(const std::vector<Event>& events) {
  v1::EventList out;
  for (const Event& e : events) {
    v1::Event* p = out.add_events();
    p->set_id(e.id);
    p->mutable_time()->set_seconds(int64_t(std::floor(e.time)));
    p->mutable_time()->set_nanos(std::min(999999999, int32_t((e.time - std::floor(e.time)) * 1e9)));
    p->set_kind(e.kind);
    p->set_job_id(e.job);
    p->set_worker(e.worker);
    p->set_who(e.who);
    p->set_detail(e.detail);
  }
  return out;
}

std::string events_json(const std::vector<Event>& events) {
  nlohmann::json list = nlohmann::json::array();
  const v1::EventList proto = to_proto(events);
  for (const v1::Event& e : proto.events())
    list.push_back({{"id", e.id()},
                    {"time", google::protobuf::util::TimeUtil::ToString(e.time())},
                    {"kind", e.kind()},
                    {"job_id", e.job_id()},
                    {"worker", e.worker()},
                    {"who", e.who()},
                    {"detail", e.detail()}});
  return lenient_dump({{"events", std::move(list)}});
}

size_t event_limit(uint32_t asked) { return asked == 0 ? 100 : std::min<uint32_t>(asked, 1000); }

}  // namespace tessera
