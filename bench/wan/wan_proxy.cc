// tessera-wan-proxy: a long, narrow link between a worker and its coordinator on one
// machine (wan_link.h). Relays 127.0.0.1:PORT to --to HOST:PORT with --rtt-ms of round trip
// (half each way) and at most --mbit megabits a second each way; SIGUSR1 cuts every open
// connection, as a dropped link would. Prints "listening on 127.0.0.1:PORT" once ready.
//
//   tessera-wan-proxy --to 127.0.0.1:7878 --rtt-ms 150 --mbit 100
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <charconv>
#include <cstdio>

#include "bench/wan/wan_link.h"
#include "core/util/cli.h"

namespace {
std::atomic<int> g_cut{0};
std::atomic<bool> g_stop{false};
void on_signal(int sig) {
  if (sig == SIGUSR1)
    ++g_cut;
  else
    g_stop = true;
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"A delayed, rate-limited TCP relay (for farm benchmarks across distances)"};
  std::string to;
  double rtt_ms = 0, mbit = 0;
  int port = 0;
  app.add_option("--to", to, "HOST:PORT to relay to")->required();
  app.add_option("--rtt-ms", rtt_ms, "round-trip delay in milliseconds (half each way)")
      ->check(tessera::finite_range(0.0, 1e5));
  app.add_option("--mbit", mbit, "bottleneck rate each way in Mbit/s (0: unlimited)")
      ->check(tessera::finite_range(0.0, 1e6));
  app.add_option("--port", port, "port to listen on, on 127.0.0.1 (0: any)")->check(CLI::Range(0, 65535));
  tessera::add_version_flag(app, "tessera-wan-proxy");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return tessera::cli_exit(app, e);
  }
  const size_t colon = to.rfind(':');
  int to_port = 0;
  const char* port_end = to.data() + to.size();
  if (colon == std::string::npos || std::from_chars(to.data() + colon + 1, port_end, to_port).ptr != port_end ||
      to_port < 1 || to_port > 65535) {
    std::fprintf(stderr, "--to: expected HOST:PORT with a port from 1 to 65535, got '%s'\n", to.c_str());
    return 2;
  }
  try {
    tessera::wan::WanLink link(to.substr(0, colon), to_port, {rtt_ms / 2000.0, mbit * 1e6 / 8}, port);
    signal(SIGUSR1, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    std::printf("listening on 127.0.0.1:%d\n", link.port());
    std::fflush(stdout);
    int cuts = 0;
    while (!g_stop) {
      usleep(20000);
      for (; cuts < g_cut; ++cuts) std::fprintf(stderr, "cut %d connection(s)\n", link.cut());
    }
    std::fprintf(stderr, "relayed %llu bytes up, %llu down over %d connection(s)\n",
                 (unsigned long long)link.bytes_up(), (unsigned long long)link.bytes_down(),
                 link.connections_accepted());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
