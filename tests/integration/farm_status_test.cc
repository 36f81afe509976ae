// The coordinator's status endpoint through a real farm: JSON, metrics, preview, page.
#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

TEST_F(Farm, StatusEndpointJsonMetricsPreviewAndPage) {
  start_coordinator();
  start_worker();
  const CommandResult r = submit_wait(kScene, "-r 64 48 -s 8 --tile 16", (dir / "x.png").string());
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json s = get_json("/api/status");
  ASSERT_NE(s, nullptr);
  ASSERT_EQ(s["jobs"].size(), 1u);
  const std::string id = s["jobs"][0]["id"];
  EXPECT_EQ(s["jobs"][0]["state"], "DONE");
  EXPECT_EQ(s["workers"].size(), 1u);
  EXPECT_GT(s["workers"][0]["samples_per_second"].get<double>(), 0);
  // The worker reported its render threads' time: busy part of it, never more than all.
  const double busy = s["workers"][0]["busy_thread_seconds"], total = s["workers"][0]["thread_seconds"];
  EXPECT_GT(busy, 0);
  EXPECT_LE(busy, total);
  EXPECT_GT(s["workers"][0]["utilization"].get<double>(), 0);
  EXPECT_LE(s["workers"][0]["utilization"].get<double>(), 1);
  // What it was given last, and when it was last heard from (the page's worker columns).
  EXPECT_TRUE(std::regex_match(s["workers"][0]["last_task"].get<std::string>(),
                               std::regex(id + R"( tile \d+ pass \d+( \(backup\))?)")))
      << s["workers"][0]["last_task"];
  EXPECT_GE(s["workers"][0]["seen_seconds_ago"].get<double>(), 0);
  EXPECT_EQ(s["workers"][0]["draining"], false);
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  EXPECT_EQ(s["workers"][0]["host"], host);  // the worker's machine, beside its name
  const nlohmann::json j = get_json("/api/jobs/" + id);
  EXPECT_EQ(j["tiles"].size(), size_t(4 * 3));  // 64x48 in 16-pixel tiles
  EXPECT_EQ(j["tiles_from"], 0);
  EXPECT_EQ(j["tiles_next"], nullptr);
  // Paged: tiles 5-8 (the second row's second on), then the last two, then none.
  const nlohmann::json p = get_json("/api/jobs/" + id + "?tiles_from=5&tiles_count=4");
  ASSERT_EQ(p["tiles"].size(), 4u);
  EXPECT_EQ(p["tiles"][0], j["tiles"][5]);
  EXPECT_EQ(p["tiles_from"], 5);
  EXPECT_EQ(p["tiles_next"], 9);
  const nlohmann::json last = get_json("/api/jobs/" + id + "?tiles_from=10");
  EXPECT_EQ(last["tiles"].size(), 2u);
  EXPECT_EQ(last["tiles_next"], nullptr);
  EXPECT_EQ(get_json("/api/jobs/" + id + "?tiles_from=99")["tiles"].size(), 0u);
  EXPECT_EQ(get_json("/api/jobs/no-such-job"), nullptr);
  httplib::Client cli("127.0.0.1", http_port);
  const auto bad = cli.Get("/api/jobs/" + id + "?tiles_count=-1");
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 400);
  EXPECT_NE(bad->body.find("tiles_count '-1' is not a whole number"), std::string::npos) << bad->body;
  // Issue 24: events, newest last, of the farm or one job; the coordinator's log has them
  // as structured lines.
  const nlohmann::json ev = get_json("/api/events?job=" + id)["events"];
  ASSERT_EQ(ev.size(), 3u) << ev;
  EXPECT_EQ(ev[0]["kind"], "job.submitted");
  EXPECT_EQ(ev[2]["kind"], "job.done");
  const nlohmann::json newest = get_json("/api/events?limit=1")["events"];
  ASSERT_EQ(newest.size(), 1u);
  EXPECT_EQ(get_json("/api/events?after=" + std::to_string(newest[0]["id"].get<uint64_t>()))["events"].size(), 0u);
  EXPECT_EQ(cli.Get("/api/events?after=x")->status, 400);
  const std::string log = slurp((dir / "coordinator1.err").string());
  EXPECT_NE(log.find("event=job.done job=" + id), std::string::npos) << log;
  EXPECT_NE(log.find("event=worker.registered worker="), std::string::npos) << log;
  // Prometheus text: comments, or `name{labels} value` with a numeric value.
  const std::string metrics = cli.Get("/metrics")->body;
  std::istringstream lines(metrics);
  int samples = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::smatch m;
    ASSERT_TRUE(std::regex_match(
        line, m, std::regex(R"(([a-z_]+)(\{([a-z_]+="([^"\\]|\\.)*",?)+\})? (-?[0-9.e+-]+|\+Inf|NaN))")))
        << line;
    if (m[5] != "+Inf" && m[5] != "NaN") std::stod(m[5]);
    ++samples;
  }
  EXPECT_GT(samples, 10);
  // Issue 24: integers exactly (not 6 significant digits), workers by name, the build, and
  // histograms of task and RPC time.
  const std::string samples_done = get_json("/api/jobs/" + id)["samples_done"].get<std::string>();
  EXPECT_NE(metrics.find("\ntessera_samples_merged_total " + samples_done + "\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_worker_tasks_total{worker=\"w0\",host=\"" + std::string(host) + "\"} "),
            std::string::npos)
      << metrics;
  EXPECT_NE(metrics.find("tessera_build_info{version=\""), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_task_seconds_bucket{le=\"+Inf\"} "), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_rpc_seconds_count{method=\"GetTask\"} "), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_jobs{state=\"done\"} 1"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_worker_utilization{worker=\""), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_workers_utilization "), std::string::npos) << metrics;
  // Autoscaling signals (issue 11): nothing left once the job is done.
  EXPECT_NE(metrics.find("tessera_queue_tasks{state=\"ready\"} 0"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_remaining_core_seconds 0"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_thread_samples_per_second "), std::string::npos) << metrics;
  // Probes for Kubernetes.
  EXPECT_EQ(cli.Get("/healthz")->status, 200);
  const auto ready = cli.Get("/readyz");
  EXPECT_EQ(ready->status, 200);
  EXPECT_EQ(ready->body, "ready\n");
  const auto png = cli.Get(("/jobs/" + id + "/preview.png").c_str());
  ASSERT_TRUE(png);
  EXPECT_EQ(png->status, 200);
  EXPECT_EQ(png->body.substr(1, 3), "PNG");
  const auto page = cli.Get("/");
  EXPECT_NE(page->body.find("<canvas"), std::string::npos);
  // Issue 10, row 8: names went into innerHTML as they were, with no policy. Now the page
  // has no inline script, a policy that forbids it, and every value written as markup is
  // escaped.
  const std::string csp = page->get_header_value("Content-Security-Policy");
  EXPECT_NE(csp.find("default-src 'none'"), std::string::npos) << csp;
  EXPECT_NE(csp.find("script-src 'self';"), std::string::npos) << csp;  // no 'unsafe-inline'
  EXPECT_EQ(csp.find("unsafe"), std::string::npos) << csp;
  EXPECT_EQ(page->body.find("<script>"), std::string::npos);
  EXPECT_EQ(png->get_header_value("X-Content-Type-Options"), "nosniff");
  const auto js = cli.Get("/app.js");
  ASSERT_TRUE(js);
  EXPECT_EQ(js->status, 200);
  std::istringstream script(js->body);
  int markup_lines = 0;
  for (std::string line; std::getline(script, line);) {
    if (line.find("innerHTML") == std::string::npos && line.find("<td>") == std::string::npos) continue;
    ++markup_lines;
    for (size_t at = line.find("${"); at != std::string::npos; at = line.find("${", at + 2))
      EXPECT_EQ(line.compare(at + 2, 4, "esc("), 0) << "unescaped value in markup: " << line.substr(at, 40);
  }
  EXPECT_GE(markup_lines, 4);
}

// Found by audit: without tokens every caller may do everything, and the page actions'
// same-origin checks compare Origin with Host, both of which a page on the attacker's own
// name carries once that name is re-pointed at this machine (DNS rebinding). Without tokens
// only addresses, localhost and names given with --http-allowed-host are answered.
TEST_F(Farm, WithoutTokensOnlyItsAddressesLocalhostAndAllowedNamesAreAnswered) {
  start_coordinator("127.0.0.1:0", "2", {"--http-allowed-host", "Render.Example."});
  httplib::Client cli("127.0.0.1", http_port);
  const std::string port = ":" + std::to_string(http_port);
  const auto get = [&](const std::string& path, const std::string& host) {
    return cli.Get(path, httplib::Headers{{"Host", host}});
  };
  auto r = get("/api/status", "evil.example" + port);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403);
  EXPECT_NE(r->body.find("Host 'evil.example" + port + "' refused"), std::string::npos) << r->body;
  EXPECT_NE(r->body.find("--http-allowed-host"), std::string::npos) << r->body;
  // The actions too, with the Origin a rebound page sends.
  r = cli.Post(
      "/api/workers/1/drain",
      httplib::Headers{
          {"Host", "evil.example" + port}, {"Origin", "http://evil.example" + port}, {"X-Tessera-Action", "1"}},
      "", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403);
  EXPECT_EQ(get("/healthz", "evil.example" + port)->status, 200);  // probes say nothing
  for (const std::string& host :
       std::vector<std::string>{"127.0.0.1" + port, "localhost" + port, "LOCALHOST", "tessera.localhost" + port,
                                "[::1]" + port, "10.1.2.3", "render.example" + port, "render.example."})
    EXPECT_EQ(get("/api/status", host)->status, 200) << host;
  for (const std::string& host : std::vector<std::string>{"render.example.evil" + port, "127.0.0.1.nip.io" + port,
                                                          "[::1" + port, "localhost:x", "1.2.3"})
    EXPECT_EQ(get("/api/status", host)->status, 403) << host;
}

}  // namespace
}  // namespace tessera
