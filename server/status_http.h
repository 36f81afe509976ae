// The coordinator's HTTP status endpoint:
//   /api/status          jobs and workers as JSON
//   /api/jobs/<id>       one job with per-tile progress, a page of tiles at a time
//                        (?tiles_from=N&tiles_count=M; kMaxTilesPage at most), and a
//                        sequence's frames likewise (?frames_from=N&frames_count=M)
//   /metrics             Prometheus text format
//   /jobs/<id>/preview.png   the latest progressive preview
//   /api/events          events (events.h), newest last: ?job=ID, ?after=ID, ?limit=N
//   /                    the live page (live_page.h): jobs, workers, events; a job's image,
//                        tiles, frames, settings and events; actions (page_actions.h)
// With access tokens, every request needs one that may read (viewer, client or admin), as
// "Authorization: Bearer TOKEN" or HTTP Basic auth with the token as the password (so a
// browser asks for it). Without them, only requests to an address, localhost or an
// allowed name are answered (host_guard.h).
#pragma once

#include <string>
#include <vector>

#include "server/auth.h"
#include "server/coordinator.h"
#include "server/http_listener.h"

namespace tessera {

// A job's status as /api/jobs/<id> gives it: protobuf's JSON (proto_json), with the tiles
// written here. protobuf's printer took 6.5 s and 0.9 GB of peak memory for the 262,144
// tiles of an 8192 x 8192 frame at tile 16; this takes the string itself. The tiles are
// those from number `tiles_from` on ("tiles_from"); "tiles_next" is where the next page
// starts, null after the last.
// A sequence's frames likewise: those from `frames_from` on, and "frames_next".
std::string job_status_json(v1::JobStatus status, uint32_t tiles_from = 0, uint32_t frames_from = 0);

class StatusHttp {
 public:
  // The status page's jobs: the ones submitted last and every live one before them (a farm
  // keeps thousands; `tessera jobs` and ListJobs page through them all).
  static constexpr size_t kStatusJobs = 200;
  // Tiles in one /api/jobs/<id> answer at most (and by default): about 2 MB of JSON.
  static constexpr uint32_t kMaxTilesPage = 16384;
  // A sequence's frames in one answer at most (and by default): a sequence of 100,000 frames
  // was 12 MB of JSON, printed every second for each open live page.
  static constexpr uint32_t kMaxFramesPage = 2000;
  // With `tls_cert` and `tls_key` (PEM files) it serves HTTPS. Throws if they do not load.
  // Without tokens it answers only requests whose Host is an address, localhost or one of
  // `allowed_hosts` (host_guard.h: DNS rebinding).
  explicit StatusHttp(Coordinator& coordinator, const Authenticator* auth = nullptr, const std::string& tls_cert = "",
                      const std::string& tls_key = "", std::vector<std::string> allowed_hosts = {});
  ~StatusHttp();
  // Binds host:port (port 0 picks one) and returns the port; throws on failure.
  int bind(const std::string& host, int port) { return http_.bind(host, port); }
  void start() { http_.start(); }  // serves on a thread until stop()
  void stop() { http_.stop(); }

  // Exposed for tests.
  std::string status_json() const;
  std::string metrics_text() const;

 private:
  Coordinator& c_;
  HttpListener http_;
};

}  // namespace tessera
