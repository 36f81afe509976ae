#include "server/status_http.h"

#include <httplib.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "server/metrics.h"

namespace tessera {
namespace {

// The live page: markup only; its style and script are served separately so that the
// Content-Security-Policy can forbid inline script (and with it any markup a job or
// worker name might smuggle in). Every value the script writes into the page goes
// through esc(), user strings and numbers alike.
const char* kLivePage = R"HTML(<!doctype html>
<html><head><meta charset="utf-8"><title>Tessera</title><link rel="stylesheet" href="/app.css"></head><body>
<h2>Tessera</h2>
<div id="summary"></div>
<div class="row"><div><h3>Image</h3><img id="preview" alt="no image yet"></div>
<div><h3>Tiles <small>(passes merged; white = finished)</small></h3><canvas id="heat"></canvas></div></div>
<div id="frames"></div>
<h3>Jobs</h3><table id="jobs"></table>
<h3>Workers</h3><table id="workers"></table>
<h3>Events</h3><table id="events"></table>
<script src="/app.js"></script></body></html>)HTML";

const char* kLiveCss = R"CSS(body{font-family:sans-serif;margin:1.5em;background:#111;color:#ddd}
table{border-collapse:collapse}td,th{padding:2px 10px;text-align:left}
.row{display:flex;gap:1.5em;align-items:flex-start}canvas,img{image-rendering:pixelated;border:1px solid #444}
#preview{max-width:48vw;max-height:60vh;height:auto}
.frame{display:inline-block;min-width:2.5em;margin:1px;padding:1px 3px;text-align:center;background:#333;color:#ddd}
.frame.DONE{background:#2a6}.frame.RUNNING{background:#c80}.frame.CANCELLED,.frame.FAILED{background:#733}
)CSS";

const char* kLiveJs = R"JS('use strict';
const esc = v => String(v).replace(/[&<>"']/g, c => ({'&':'&amp;','<':'&lt;','>':'&gt;','"':'&quot;',"'":'&#39;'}[c]));
let heat = {id: null, from: 0};  // the tile map's job and next page
async function tick(){
  const s = await (await fetch('/api/status')).json();
  const jobs = s.jobs || [], workers = s.workers || [];
  document.getElementById('summary').textContent =
    `${jobs.length} jobs, ${workers.filter(w=>w.active).length} active workers, ` +
    `${(100*s.utilization).toFixed(0)}% busy, up ${s.uptime_seconds.toFixed(0)} s`;
  const when = t => t ? new Date(t).toLocaleString() : '-';
  document.getElementById('jobs').innerHTML = '<tr><th>id</th><th>name</th><th>owner</th><th>priority</th><th>state</th><th>samples</th><th>passes / frames</th><th>submitted</th><th>ended</th><th>elapsed</th><th>ETA</th></tr>' +
    jobs.map(j=>`<tr><td>${esc(j.id)}</td><td>${esc(j.name)}</td><td>${esc(j.owner || '-')}</td><td>${esc(j.priority || 0)}</td><td>${esc(j.state)}</td><td>${esc((100*j.samples_done/Math.max(1,j.samples_total)).toFixed(1))}%</td><td>${esc(j.frames_total ? 'frames ' + j.frames_done + '/' + j.frames_total : j.frame_passes_done + '/' + j.passes_total)}</td><td>${esc(when(j.submitted_at))}</td><td>${esc(when(j.ended_at))}</td><td>${esc(j.elapsed_seconds.toFixed(0))} s</td><td>${esc(j.eta_seconds.toFixed(0))} s</td></tr>`).join('');
  document.getElementById('workers').innerHTML = '<tr><th>id</th><th>name</th><th>threads</th><th>samples/s</th><th>busy</th><th>tasks</th><th>leases</th><th>round trip</th><th>bytes/sample</th><th>passes/task</th></tr>' +
    workers.map(w=>`<tr><td>${esc(w.id)}</td><td>${esc(w.name)}</td><td>${esc(w.threads)}</td><td>${esc((w.samples_per_second/1e6).toFixed(2))} M</td><td>${esc((100*w.utilization).toFixed(0))}%</td><td>${esc(w.tasks_done)}</td><td>${esc(w.leases)}</td><td>${esc(w.round_trip_ms.toFixed(1))} ms</td><td>${esc(w.bytes_per_sample.toFixed(3))}</td><td>${esc(w.passes_per_task)}</td></tr>`).join('');
  const ev = (await (await fetch('/api/events?limit=20')).json()).events || [];
  document.getElementById('events').innerHTML = '<tr><th>time</th><th>event</th><th>job</th><th>worker</th><th>who</th><th>detail</th></tr>' +
    ev.reverse().map(e=>`<tr><td>${esc(when(e.time))}</td><td>${esc(e.kind)}</td><td>${esc(e.job_id || '-')}</td><td>${esc(e.worker || '-')}</td><td>${esc(e.who || '-')}</td><td>${esc(e.detail)}</td></tr>`).join('');
  const job = jobs.find(j=>j.state==='RUNNING') || jobs[jobs.length-1];
  if (!job) return;
  // The tile map a page of tiles per tick (the API's tiles_next), redrawn from the first.
  const tiles = id => `/api/jobs/${encodeURIComponent(id)}?tiles_from=${heat.id === id ? heat.from : 0}`;
  let id = job.id, d = await (await fetch(tiles(id))).json();
  // A sequence: every frame by state (a finished one opens its image), and the frame being
  // rendered (else the last one started) in the preview and the tile map.
  const frames = d.frames || [];
  document.getElementById('frames').innerHTML = frames.length === 0 ? '' : '<h3>Frames</h3>' + frames.map(f =>
    f.state === 'DONE'
      ? `<a class="frame DONE" href="/jobs/${esc(encodeURIComponent(f.job_id))}/preview.png">${esc(f.frame)}</a>`
      : `<span class="frame ${esc(f.state)}" title="${esc(f.state)}">${esc(f.frame)}</span>`).join('');
  if (frames.length) {
    const f = frames.find(f=>f.state==='RUNNING') || [...frames].reverse().find(f=>f.job_id);
    if (!f) return;
    id = f.job_id;
    d = await (await fetch(tiles(id))).json();
  }
  document.getElementById('preview').src = `/jobs/${encodeURIComponent(id)}/preview.png?t=${Date.now()}`;
  const c = document.getElementById('heat'), ctx = c.getContext('2d');
  if (d.tiles_from === 0) {
    c.width = d.settings.width; c.height = d.settings.height;
    ctx.fillStyle = '#000'; ctx.fillRect(0, 0, c.width, c.height);
  }
  heat = {id, from: d.tiles_next ?? 0};
  for (const t of d.tiles || []) {
    const f = t.passes_done / Math.max(1, d.passes_total);
    ctx.fillStyle = t.finished ? '#fff' : `hsl(${240 - 240*f},80%,${25+35*f}%)`;
    ctx.fillRect((t.rect.x||0) + 1, (t.rect.y||0) + 1, t.rect.w - 2, t.rect.h - 2);  // 1-px gaps show tiles
  }
}
tick(); setInterval(tick, 1000);
)JS";

// Only this server's own script, style, images and API; no inline script, no framing.
const char* kContentSecurityPolicy =
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; connect-src 'self'; "
    "base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

}  // namespace

std::string job_status_json(v1::JobStatus status, uint32_t tiles_from) {
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
         ",\"tiles_next\":" + (!tiles.empty() && next < status.tiles_total() ? std::to_string(next) : "null") + "}";
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
  res.set_content(nlohmann::json{{"error", std::string(name) + " '" + v + "' is not a whole number"}}.dump(),
                  "application/json");
  return false;
}

std::unique_ptr<httplib::Server> make_server(const std::string& cert, const std::string& key) {
  if (cert.empty() && key.empty()) return std::make_unique<httplib::Server>();
  auto tls = std::make_unique<httplib::SSLServer>(cert.c_str(), key.c_str());
  if (!tls->is_valid()) throw std::runtime_error("http: cannot load the TLS certificate " + cert + " and key " + key);
  return tls;
}
}  // namespace

StatusHttp::StatusHttp(Coordinator& c, const Authenticator* auth, const std::string& tls_cert,
                       const std::string& tls_key)
    : c_(c), http_(make_server(tls_cert, tls_key), "http") {
  httplib::Server& server = http_.server();
  if (auth && auth->enabled())
    server.set_pre_routing_handler([auth](const httplib::Request& req, httplib::Response& res) {
      // Probes (kubelet, load balancers) carry no token, and the answers say nothing.
      if (req.path == "/healthz" || req.path == "/readyz") return httplib::Server::HandlerResponse::Unhandled;
      const Authenticator::Check c = auth->check(req.get_header_value("Authorization"), Action::kRead);
      if (c.outcome == Authenticator::Check::kAllowed) return httplib::Server::HandlerResponse::Unhandled;
      const bool unauthenticated = c.outcome == Authenticator::Check::kUnauthenticated;
      res.status = unauthenticated ? 401 : 403;
      if (unauthenticated) res.set_header("WWW-Authenticate", "Basic realm=\"tessera\", charset=\"UTF-8\"");
      res.set_content(c.why + (unauthenticated ? " (Authorization: Bearer TOKEN)\n" : "\n"), "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    });
  add_probes(server, c_);
  server.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(status_json(), "application/json");
  });
  server.Get(R"(/api/jobs/([A-Za-z0-9-]+))", [this](const httplib::Request& req, httplib::Response& res) {
    TileRange range{0, kMaxTilesPage};
    if (!whole_param(req, res, "tiles_from", &range.from) || !whole_param(req, res, "tiles_count", &range.count))
      return;
    range.count = std::min(range.count, kMaxTilesPage);
    try {
      res.set_content(job_status_json(c_.status(req.matches[1], true, range), range.from), "application/json");
    } catch (const RequestError& e) {
      res.status = 404;
      res.set_content(nlohmann::json{{"error", e.what()}}.dump(), "application/json");
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

std::string StatusHttp::status_json() const {
  // Written out directly: with thousands of workers, building a JSON object per worker
  // was most of the endpoint's time.
  std::string out;
  char buf[2304];  // a worker's name is at most 256 characters, at most 6 each escaped
  auto num = [](double v) { return std::isfinite(v) ? v : 0.0; };
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
  out.reserve(out.size() + workers.size() * 280);
  for (size_t i = 0; i < workers.size(); ++i) {
    const WorkerInfo& w = workers[i];
    std::snprintf(buf, sizeof buf,
                  "%s{\"id\":%llu,\"name\":%s,\"threads\":%u,\"samples_per_second\":%.17g,\"tasks_done\":%llu,"
                  "\"leases\":%u,\"active\":%s,\"busy_thread_seconds\":%.17g,\"thread_seconds\":%.17g,"
                  "\"utilization\":%.17g,\"round_trip_ms\":%.17g,\"result_bytes\":%llu,\"bytes_per_sample\":%.17g,"
                  "\"passes_per_task\":%u}",
                  i ? "," : "", (unsigned long long)w.id, nlohmann::json(w.name).dump().c_str(), w.threads,
                  num(w.samples_per_second), (unsigned long long)w.tasks_done, w.leases, w.leases ? "true" : "false",
                  num(w.busy_thread_seconds), num(w.thread_seconds), num(w.utilization), num(w.round_trip * 1e3),
                  (unsigned long long)w.result_bytes,
                  w.result_samples ? double(w.result_bytes) / double(w.result_samples) : 0.0, w.passes_per_task);
    out += buf;
  }
  out += "]}";
  return out;
}

std::string StatusHttp::metrics_text() const { return prometheus_text(c_); }

}  // namespace tessera
