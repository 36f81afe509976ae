#include "server/status_http.h"

#include <httplib.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/util/text.h"
#include "server/host_guard.h"
#include "server/json_text.h"
#include "server/live_page.h"
#include "server/metrics.h"
#include "server/page_actions.h"

namespace tessera {
namespace {

// Only this server's own script, style, images and API; no inline script, no framing.
const char* kContentSecurityPolicy =
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob:; connect-src 'self'; "
    "base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

}  // namespace

std::string job_status_json(v1::JobStatus status, uint32_t tiles_from, uint32_t frames_from) {
  google::protobuf::RepeatedPtrField<v1::TileProgress> tiles;
  tiles.Swap(status.mutable_tiles());
  std::string out = proto_json(status);  // "{...}": every field printed, so never "{}"
  out.pop_back();
  out += ",\"tiles\":[";
  char buf[192], err[32];
  for (int i = 0; i < tiles.size(); ++i) {
    const v1::TileProgress& t = tiles[i];
    const float e = t.relative_error();
    if (std::isfinite(e))  // as protobuf prints them: shortest form that reads back, else a string
      std::snprintf(err, sizeof err, "%.9g", double(e));
    else
      std::snprintf(err, sizeof err, "\"%s\"", std::isnan(e) ? "NaN" : e > 0 ? "Infinity" : "-Infinity");
    const int n = std::snprintf(buf, sizeof buf,
                                "%s{\"finished\":%s,\"passes_done\":%u,\"rect\":{\"h\":%u,\"w\":%u,\"x\":%u,\"y\":%u},"
                                "\"relative_error\":%s,\"samples\":%u}",
                                i ? "," : "", t.finished() ? "true" : "false", t.passes_done(), t.rect().h(),
                                t.rect().w(), t.rect().x(), t.rect().y(), err, t.samples());
    out.append(buf, size_t(n));
  }
  const uint64_t next = uint64_t(tiles_from) + uint64_t(tiles.size());
  out += "],\"tiles_from\":" + std::to_string(tiles_from) +
         ",\"tiles_next\":" + (!tiles.empty() && next < status.tiles_total() ? std::to_string(next) : "null");
  if (status.frames_total() > 0) {
    const uint64_t frames_next = uint64_t(frames_from) + uint64_t(status.frames_size());
    out += ",\"frames_from\":" + std::to_string(frames_from) + ",\"frames_next\":" +
           (status.frames_size() > 0 && frames_next < status.frames_total() ? std::to_string(frames_next) : "null");
  }
  out += "}";
  return out;
}

namespace {

// The query parameter `name`, when given, as a whole number into `value`; false (and a 400
// answer naming it) when it is not one.
template <typename T>
bool whole_param(const httplib::Request& req, httplib::Response& res, const char* name, T* value) {
  if (!req.has_param(name)) return true;
  const std::string v = req.get_param_value(name);
  const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), *value);
  if (ec == std::errc() && end == v.data() + v.size()) return true;
  res.status = 400;
  res.set_content(lenient_dump({{"error", std::string(name) + " '" + utf8_prefix(v, 64) + "' is not a whole number"}}),
                  "application/json");
  return false;
}

// /healthz and /readyz: answered to anyone (kubelet, load balancers), with or without a
// token, whatever the Host; they say nothing else.
bool is_probe(const std::string& path) { return path == "/healthz" || path == "/readyz"; }

std::unique_ptr<httplib::Server> make_server(const std::string& cert, const std::string& key) {
  if (cert.empty() && key.empty()) return std::make_unique<httplib::Server>();
  auto tls = std::make_unique<httplib::SSLServer>(cert.c_str(), key.c_str());
  if (!tls->is_valid()) throw std::runtime_error("http: cannot load the TLS certificate " + cert + " and key " + key);
  return tls;
}
}  // namespace

StatusHttp::StatusHttp(Coordinator& c, const Authenticator* auth, const std::string& tls_cert,
                       const std::string& tls_key, std::vector<std::string> allowed_hosts)
    : c_(c), http_(make_server(tls_cert, tls_key), "http") {
  httplib::Server& server = http_.server();
  if (!auth || !auth->enabled())
    server.set_pre_routing_handler(
        [allowed = std::move(allowed_hosts)](const httplib::Request& req, httplib::Response& res) {
          if (is_probe(req.path)) return httplib::Server::HandlerResponse::Unhandled;
          const std::string host = req.get_header_value("Host");
          if (host_allowed(host, allowed)) return httplib::Server::HandlerResponse::Unhandled;
          res.status = 403;
          res.set_content("Host '" + peer_text(host, 256) +
                              "' refused: without access tokens this server answers only its addresses, localhost and "
                              "the names --http-allowed-host gives (a web page elsewhere could point such a name here: "
                              "DNS rebinding)\n",
                          "text/plain");
          return httplib::Server::HandlerResponse::Handled;
        });
  else
    server.set_pre_routing_handler([auth](const httplib::Request& req, httplib::Response& res) {
      if (is_probe(req.path)) return httplib::Server::HandlerResponse::Unhandled;
      const Authenticator::Check c = auth->check(req.get_header_value("Authorization"), Action::kRead);
      if (c.outcome == Authenticator::Check::kAllowed) return httplib::Server::HandlerResponse::Unhandled;
      const bool unauthenticated = c.outcome == Authenticator::Check::kUnauthenticated;
      res.status = unauthenticated ? 401 : 403;
      if (unauthenticated) res.set_header("WWW-Authenticate", "Basic realm=\"tessera\", charset=\"UTF-8\"");
      res.set_content(c.why + (unauthenticated ? " (Authorization: Bearer TOKEN)\n" : "\n"), "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    });
  add_probes(server, c_);
  add_page_actions(server, c_, auth);
  server.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(status_json(), "application/json");
  });
  server.Get(R"(/api/jobs/([A-Za-z0-9-]+))", [this](const httplib::Request& req, httplib::Response& res) {
    TileRange range{0, kMaxTilesPage};
    FrameRange frames{0, kMaxFramesPage};
    if (!whole_param(req, res, "tiles_from", &range.from) || !whole_param(req, res, "tiles_count", &range.count) ||
        !whole_param(req, res, "frames_from", &frames.from) || !whole_param(req, res, "frames_count", &frames.count))
      return;
    range.count = std::min(range.count, kMaxTilesPage);
    frames.count = std::min(frames.count, kMaxFramesPage);
    try {
      res.set_content(job_status_json(c_.status(req.matches[1], true, range, frames), range.from, frames.from),
                      "application/json");
    } catch (const RequestError& e) {
      res.status = 404;
      res.set_content(lenient_dump({{"error", e.what()}}), "application/json");
    }
  });
  // Events (events.h), newest last: ?job=ID (that job's), ?after=ID (newer ones), ?limit=N.
  server.Get("/api/events", [this](const httplib::Request& req, httplib::Response& res) {
    uint64_t after = 0, limit = 0;
    if (!whole_param(req, res, "after", &after) || !whole_param(req, res, "limit", &limit)) return;
    const std::string job = req.has_param("job") ? req.get_param_value("job") : "";
    const auto events = c_.events(job, after, event_limit(uint32_t(std::min<uint64_t>(limit, 1000))), true);
    res.set_content(events_json(events), "application/json");
  });
  server.Get("/metrics", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(metrics_text(), "text/plain; version=0.0.4");
  });
  server.Get(R"(/jobs/([A-Za-z0-9-]+)/preview.png)", [this](const httplib::Request& req, httplib::Response& res) {
    std::string png;
    try {
      png = c_.image(req.matches[1], false, true).png();
    } catch (const RequestError& e) {
      res.status = 404;
      res.set_content(e.what(), "text/plain");
      return;
    }
    if (png.empty()) {
      res.status = 404;
      res.set_content("no image yet", "text/plain");
      return;
    }
    res.set_header("Cache-Control", "no-store");
    res.set_content(png, "image/png");
  });
  server.Get("/", [](const httplib::Request&, httplib::Response& res) { res.set_content(kLivePage, "text/html"); });
  server.Get("/app.js",
             [](const httplib::Request&, httplib::Response& res) { res.set_content(kLiveJs, "text/javascript"); });
  server.Get("/app.css",
             [](const httplib::Request&, httplib::Response& res) { res.set_content(kLiveCss, "text/css"); });
  // Every response: the policy, and no content-type guessing by browsers.
  server.set_post_routing_handler([](const httplib::Request&, httplib::Response& res) {
    res.set_header("Content-Security-Policy", kContentSecurityPolicy);
    res.set_header("X-Content-Type-Options", "nosniff");
  });
}

StatusHttp::~StatusHttp() { stop(); }  // before anything its handlers reach goes

namespace {
// What the worker was given last, as the page shows it: "JOB tile T pass P" ("" before any).
std::string last_task(const WorkerInfo& w) {
  if (w.last_job.empty()) return "";
  return w.last_job + " tile " + std::to_string(w.last_tile) + " pass " + std::to_string(w.last_pass) +
         (w.last_backup ? " (backup)" : "");
}
}  // namespace

std::string StatusHttp::status_json() const {
  // Written out directly: with thousands of workers, building a JSON object per worker
  // was most of the endpoint's time.
  std::string out;
  char buf[8192];  // a worker's name, host and last task: at most 256 characters each, 6 bytes each escaped
  auto num = [](double v) { return std::isfinite(v) ? v : 0.0; };
  auto text = [](const std::string& v) { return lenient_dump(v); };
  std::snprintf(buf, sizeof buf, "{\"uptime_seconds\":%.17g,\"utilization\":%.17g,\"jobs\":[", num(c_.uptime()),
                num(c_.utilization()));
  out += buf;
  const std::vector<v1::JobStatus> jobs = c_.recent(kStatusJobs);
  for (size_t i = 0; i < jobs.size(); ++i) {
    if (i) out += ',';
    out += proto_json(jobs[i]);
  }
  out += "],\"workers\":[";
  const std::vector<WorkerInfo> workers = c_.workers();
  const double now = c_.now();
  out.reserve(out.size() + workers.size() * 280);
  for (size_t i = 0; i < workers.size(); ++i) {
    const WorkerInfo& w = workers[i];
    std::snprintf(
        buf, sizeof buf,
        "%s{\"id\":%llu,\"name\":%s,\"host\":%s,\"threads\":%u,\"samples_per_second\":%.17g,\"tasks_done\":%llu,"
        "\"leases\":%u,\"active\":%s,\"busy_thread_seconds\":%.17g,\"thread_seconds\":%.17g,"
        "\"utilization\":%.17g,\"round_trip_ms\":%.17g,\"result_bytes\":%llu,\"bytes_per_sample\":%.17g,"
        "\"passes_per_task\":%u,\"draining\":%s,\"seen_seconds_ago\":%.17g,\"last_task\":%s}",
        i ? "," : "", (unsigned long long)w.id, text(w.name).c_str(), text(w.host).c_str(), w.threads,
        num(w.samples_per_second), (unsigned long long)w.tasks_done, w.leases, w.leases ? "true" : "false",
        num(w.busy_thread_seconds), num(w.thread_seconds), num(w.utilization), num(w.round_trip * 1e3),
        (unsigned long long)w.result_bytes, w.result_samples ? double(w.result_bytes) / double(w.result_samples) : 0.0,
        w.passes_per_task, w.draining ? "true" : "false", num(now - w.last_seen), text(last_task(w)).c_str());
    out += buf;
  }
  out += "]}";
  return out;
}

std::string StatusHttp::metrics_text() const { return prometheus_text(c_); }

}  // namespace tessera
