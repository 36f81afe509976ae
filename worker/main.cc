// tessera-worker: renders tiles for a coordinator.
#include <signal.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>

#include "core/util/cli.h"
#include "core/util/log.h"
#include "core/util/memory.h"
#include "worker/worker.h"

namespace {
std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tessera-worker: renders tiles for a Tessera coordinator"};
  tessera::WorkerOptions opt;
  app.add_option("--coordinator", opt.coordinator, "coordinator gRPC address HOST:PORT (else $TESSERA_COORDINATOR)")
      ->envname("TESSERA_COORDINATOR")
      ->required();
  app.add_option("-t,--threads", opt.threads, "render threads (0 = every core)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  app.add_option("--cache", opt.cache_dir, "scene cache directory")->capture_default_str();
  app.add_option("--cache-max-gib", opt.cache_max_gib,
                 "the scene cache's size on disk at most, in GiB: least recently used scenes are removed after a "
                 "fetch (never one in use or used in the last hour); 0: no bound")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 1e9));
  app.add_option("--max-memory-gib", opt.max_memory_gib,
                 "renderers kept for later tasks (and their scenes) are dropped, oldest first, while the worker's "
                 "resident memory is above this many GiB (default: half the memory it may use, a container's limit "
                 "where lower; 0: no bound)")
      ->check(tessera::finite_range(0.0, 1e9));
  app.add_option("--name", opt.name,
                 "name shown by the coordinator and in /metrics (default host:pid, in a Slurm job host:slurm-JOBID)");
  app.add_option("--lookahead-seconds", opt.lookahead_seconds,
                 "seconds of work to keep leased beyond what the threads are rendering, at the measured speed")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 60.0));
  tessera::add_old_spelling(app, "--lookahead", "--lookahead-seconds", opt.lookahead_seconds)
      ->check(tessera::finite_range(0.0, 60.0));
  app.add_option("--max-leases", opt.max_tasks,
                 "leases held at once, at most (0: as the window of work in flight asks, up to the coordinator's "
                 "bound)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  tessera::add_old_spelling(app, "--max-tasks", "--max-leases", opt.max_tasks)->check(CLI::Range(0, 1000000));
  app.add_option("--passes-per-task", opt.passes_per_task,
                 "passes of a tile rendered and sent as one result, where the job allows (no -a, no "
                 "--noise-target); 0: as the link needs (more when the coordinator is far or results outrun "
                 "the link)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
  app.add_flag("-v,--verbose", opt.verbose, "log connection events");
  app.add_option("--exit-when-idle-seconds", opt.exit_when_idle_seconds,
                 "leave after this many seconds without a task (0: never); for batch allocations")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 1e9));
  tessera::add_old_spelling(app, "--exit-when-idle", "--exit-when-idle-seconds", opt.exit_when_idle_seconds)
      ->check(tessera::finite_range(0.0, 1e9));
  app.add_flag("--test-lie", opt.lie)->group("");  // verification tests: wrong sums
  std::string token_file, tls_ca;
  app.add_option("--token-file", token_file,
                 "file holding a worker access token (else $TESSERA_TOKEN_FILE, or the token in $TESSERA_TOKEN)");
  app.add_option("--tls-ca", tls_ca, "PEM certificate authority: connect over TLS (else $TESSERA_TLS_CA)");
  std::string enrol_file;
  app.add_option("--enrol-token-file", enrol_file,
                 "file holding an enrolment token: the worker enrols under --name for a credential of its own "
                 "(docs/security.md; else $TESSERA_ENROL_TOKEN_FILE)")
      ->envname("TESSERA_ENROL_TOKEN_FILE");
  tessera::add_version_flag(app, "tessera-worker");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return tessera::cli_exit(app, e);
  }
  if (app.count("--max-memory-gib") == 0)  // half the memory it may use (a container's limit, if lower)
    opt.max_memory_gib = double(tessera::usable_memory_bytes()) / 2 / double(uint64_t(1) << 30);
  tessera::init_logging("tessera-worker", opt.verbose);
  try {
    opt.access = tessera::load_access(token_file, tls_ca);
    if (!enrol_file.empty()) opt.enrol_token = tessera::read_token_file(enrol_file);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 2;
  }
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
  try {
    tessera::Worker worker(opt);
    const bool ok = worker.run(g_stop);
    spdlog::info("stopped after {} tasks", worker.tasks_done());
    if (!ok) return 1;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
