// tessera-coordinator: splits frames into tiles, leases them to workers, merges results.
#include <grpcpp/grpcpp.h>
#include <malloc.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <optional>
#include <thread>

#include "core/io/files.h"
#include "core/util/cancel.h"
#include "core/util/cli.h"
#include "core/util/log.h"
#include "core/util/memory.h"
#include "server/admission.h"
#include "server/grpc_services.h"
#include "server/health_http.h"
#include "server/scene_loads.h"
#include "server/status_http.h"

namespace {

// Every connection and every file being written is a descriptor: the soft limit goes up
// to the hard one (systemd's default soft limit, 1024, ran out at about a thousand idle
// connections, and then checkpoints failed), with a warning if that is still low.
void raise_fd_limit() {
  rlimit r{};
  if (getrlimit(RLIMIT_NOFILE, &r) != 0) return;
  if (r.rlim_cur < r.rlim_max) {
    r.rlim_cur = r.rlim_max;
    setrlimit(RLIMIT_NOFILE, &r);
    getrlimit(RLIMIT_NOFILE, &r);
  }
  if (r.rlim_cur < 4096)
    spdlog::warn(
        "only {} file descriptors (every connection takes one): raise the limit (LimitNOFILE= in the "
        "systemd unit, ulimit -n)",
        (unsigned long long)r.rlim_cur);
}

std::pair<std::string, int> split_host_port(const std::string& s, const char* flag) {
  const size_t colon = s.rfind(':');
  if (colon == std::string::npos) throw CLI::ValidationError(flag, "expected HOST:PORT, got '" + s + "'");
  try {
    const int port = std::stoi(s.substr(colon + 1));
    if (port < 0 || port > 65535) throw std::out_of_range("port");
    return {s.substr(0, colon), port};
  } catch (const std::exception&) {
    throw CLI::ValidationError(flag, "bad port in '" + s + "'");
  }
}

// Loopback only: 127.0.0.0/8, ::1 and localhost.
bool is_loopback(const std::string& host) {
  return host.rfind("127.", 0) == 0 || host == "localhost" || host == "::1" || host == "[::1]";
}

// "7d", "12h", "30m", "45s" or plain seconds; "forever" (or 0) is no limit.
double parse_keep(const std::string& s) {
  if (s == "forever") return 0;
  size_t end = 0;
  double v = 0;
  try {
    v = std::stod(s, &end);
  } catch (const std::exception&) {
    end = 0;
  }
  const std::string unit = s.substr(end);
  const double scale = unit == "d"                   ? 86400
                       : unit == "h"                 ? 3600
                       : unit == "m"                 ? 60
                       : unit == "s" || unit.empty() ? 1
                                                     : -1;
  if (end == 0 || scale < 0 || !(v >= 0) || v * scale > 1e10)
    throw CLI::ValidationError("--keep-ended",
                               "expected a duration such as 7d, 12h, 30m, 45s or forever, got '" + s + "'");
  return v * scale;
}

// glibc gives each of up to 8 x cores threads that allocate at once a heap of its own and
// keeps what they free: the coordinator's gRPC threads (a watcher's status, an image's
// pieces) grew it by tens of MB that stayed. Its work is under one lock anyway, so a few
// heaps cost nothing measurable (docs/performance.md); MALLOC_ARENA_MAX still decides.
constexpr int kMallocArenas = 4;

}  // namespace

int main(int argc, char** argv) {
  if (!std::getenv("MALLOC_ARENA_MAX")) mallopt(M_ARENA_MAX, kMallocArenas);
  CLI::App app{"tessera-coordinator: the render farm's coordinator"};
  std::string listen = "127.0.0.1:7878", http = "127.0.0.1:7879";
  tessera::CoordinatorOptions opt;
  app.add_option("--listen", listen, "gRPC address HOST:PORT (port 0 picks a free port)")->capture_default_str();
  app.add_option("--http", http, "status endpoint HOST:PORT (port 0 picks a free port)")->capture_default_str();
  std::vector<std::string> allowed_hosts;
  app.add_option("--http-allowed-host", allowed_hosts,
                 "without --tokens-file, a host name the status endpoint answers to besides its addresses and "
                 "localhost (repeat for more; guards against DNS rebinding)");
  std::string health;
  app.add_option("--health", health,
                 "probes' own listener HOST:PORT (/healthz, /readyz on their own threads: answered whatever holds the "
                 "status port)");
  app.add_option("--data", opt.data_dir,
                 "data directory (job database, scenes, images, checkpoints); a coordinator started again on it "
                 "takes up its jobs")
      ->capture_default_str();
  app.add_option("--checkpoint-seconds", opt.checkpoint_seconds,
                 "save running jobs' films at least this often: what a crash can cost")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 3600.0));
  app.add_option("--verify-fraction", opt.verify_fraction,
                 "render this fraction of tasks again on a second worker and compare the bits; a worker that "
                 "differs from the coordinator's own render is quarantined (0 turns it off)")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 1.0));
  app.add_option("--verify-first", opt.verify_first,
                 "check every one of a newly registered worker's first this many tasks (probation), whatever "
                 "--verify-fraction picks")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000000));
  tessera::ConnectionLimits connection_limits;
  app.add_option("--handshake-seconds", connection_limits.handshake_seconds,
                 "close a gRPC connection that has not finished its handshake (TLS included) in this long")
      ->capture_default_str()
      ->check(tessera::finite_range(0.1, 3600.0));
  app.add_option("--idle-connection-seconds", connection_limits.idle_seconds,
                 "close a gRPC connection with no call for this long (clients reconnect by themselves)")
      ->capture_default_str()
      ->check(tessera::finite_range(1.0, 86400.0));
  int write_delay_ms = 0, commit_delay_ms = 0;  // for the crash tests: windows in which to kill
  app.add_option("--test-checkpoint-delay-ms", write_delay_ms)->group("")->check(CLI::Range(0, 60000));
  app.add_option("--test-commit-delay-ms", commit_delay_ms)->group("")->check(CLI::Range(0, 60000));
  std::string keep_ended = "7d";
  app.add_option("--keep-ended", keep_ended,
                 "delete ended jobs (record, images, checkpoints, scene if no other job uses it) this long after "
                 "they end: 7d, 12h, 30m, 45s, or forever")
      ->capture_default_str();
  app.add_option("--lease-seconds", opt.lease_seconds, "lease length; a silent worker's task moves on after it")
      ->capture_default_str()
      ->check(tessera::finite_range(0.1, 3600.0));
  app.add_option("--max-task-seconds", opt.max_task_seconds,
                 "a task's time from its lease to its result, at most: past it the task counts as failed on its "
                 "worker (the job fails once tasks fail on two workers); 0: no bound")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 1e7));
  app.add_option("--max-scene-loads", opt.max_scene_loads,
                 "scenes the coordinator loads at once (to check a submit, requeue or restore, or to render a check), "
                 "at most; the rest wait their turn (default: one per 16 GiB of memory, 1 to 4)")
      ->check(CLI::Range(1, 1024));
  app.add_option("--max-workers", opt.max_workers, "registered workers at most (silent ones are forgotten after 60 s)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--max-workers-per-token", opt.max_workers_per_token,
                 "registered workers of one worker token at most (with --tokens-file)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--max-leases-per-worker", opt.max_leases_per_worker,
                 "leases one worker may hold at once (its window of work in flight grows with its round trip, up "
                 "to this)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--max-streams-per-peer", opt.max_streams_per_peer,
                 "streams one caller may hold open at once: a client's job watches, image downloads and scene "
                 "uploads (per token, or without tokens per address); a worker's scene downloads (per enrolled "
                 "worker, or per worker token and address)")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  app.add_option("--max-jobs-per-client", opt.max_jobs_per_client, "live jobs one client token may have at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--max-live-pixels", opt.max_live_pixels,
                 "pixels of all live frames together (each costs 40 bytes of memory; default: 2^27, or half the "
                 "machine's memory if less)")
      ->capture_default_str()
      ->check(CLI::Range(int64_t(1), int64_t(1) << 40));
  app.add_option("--max-scene-bytes-per-client", opt.max_scene_bytes_per_client,
                 "scene bytes of one client's live jobs and scene uploads together, at most")
      ->capture_default_str()
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 50));
  app.add_option("--max-queued-samples-per-client", opt.max_queued_samples_per_client,
                 "camera samples still to render of one client's live jobs together, at most")
      ->capture_default_str()
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 62));
  app.add_option("--image-interval-seconds", opt.image_interval_seconds, "write progressive images at most this often")
      ->capture_default_str()
      ->check(tessera::finite_range(0.0, 86400.0));
  tessera::add_old_spelling(app, "--image-interval", "--image-interval-seconds", opt.image_interval_seconds)
      ->check(tessera::finite_range(0.0, 86400.0));
  std::string tokens_file, tls_cert, tls_key;
  bool insecure = false;
  app.add_option("--tokens-file", tokens_file,
                 "access tokens, one 'ROLE NAME TOKEN' a line (roles: viewer, client, worker, enrol, admin); "
                 "else $TESSERA_TOKENS_FILE")
      ->envname("TESSERA_TOKENS_FILE")
      ->check(CLI::ExistingFile);
  tessera::add_old_spelling(app, "--tokens", "--tokens-file", tokens_file)->check(CLI::ExistingFile);
  app.add_option("--tls-cert", tls_cert, "PEM certificate chain: serve gRPC and HTTP over TLS")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", tls_key, "PEM private key of --tls-cert")->check(CLI::ExistingFile);
  app.add_flag("--insecure", insecure,
               "allow listening beyond loopback without access tokens (anyone who can connect may do anything)");
  tessera::add_version_flag(app, "tessera-coordinator");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return tessera::cli_exit(app, e);
  }
  if (app.count("--max-live-pixels") == 0)  // a frame the machine cannot hold is refused at submit
    opt.max_live_pixels = tessera::live_pixel_default(tessera::usable_memory_bytes());
  if (app.count("--max-scene-loads") == 0)  // each load may take gigabytes within the loaders' budgets
    opt.max_scene_loads = tessera::scene_load_default(tessera::usable_memory_bytes());
  tessera::init_logging("tessera-coordinator");
  if (tls_cert.empty() != tls_key.empty()) {
    spdlog::error("--tls-cert and --tls-key go together");
    return 2;
  }
  opt.heartbeat_seconds = std::min(2.0, opt.lease_seconds / 4);
  double keep_seconds = 0;
  try {
    keep_seconds = parse_keep(keep_ended);
  } catch (const CLI::ValidationError& e) {
    spdlog::error("{}", e.what());
    return 2;
  }

  // Block the stop signals in every thread; main waits for them below.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  raise_fd_limit();
  try {
    const auto [grpc_host, grpc_port] = split_host_port(listen, "--listen");
    const auto [http_host, http_port] = split_host_port(http, "--http");
    // Checked with the others, before any port or the data folder is opened.
    const std::optional<std::pair<std::string, int>> health_at =
        health.empty() ? std::nullopt : std::optional(split_host_port(health, "--health"));
    tessera::Authenticator auth =
        tokens_file.empty() ? tessera::Authenticator() : tessera::Authenticator::from_file(tokens_file);
    const bool open_network = !is_loopback(grpc_host) || !is_loopback(http_host);
    if (!auth.enabled()) {
      if (open_network && !insecure) {
        spdlog::error(
            "refusing to listen beyond loopback ({}, {}) without access tokens: give --tokens-file FILE, or --insecure "
            "to allow anyone who can connect to do anything",
            listen, http);
        return 2;
      }
      spdlog::warn("no access tokens: every caller may do anything ({})",
                   open_network ? "--insecure, reachable beyond loopback" : "loopback only");
    } else {
      if (open_network && tls_cert.empty())
        spdlog::warn(
            "access tokens travel in clear beyond loopback ({}, {}): anyone on the path can read and reuse them; "
            "give --tls-cert and --tls-key (docs/security.md, TLS)",
            listen, http);
      const auto perms = std::filesystem::status(tokens_file).permissions();
      if ((perms & std::filesystem::perms::others_read) != std::filesystem::perms::none)
        spdlog::warn(
            "tokens file {} is readable by every user of this machine: chmod o-r it (Kubernetes: the "
            "Secret volume's defaultMode, 0440 in deploy/k8s)",
            tokens_file);
    }
    std::shared_ptr<grpc::ServerCredentials> credentials = grpc::InsecureServerCredentials();
    if (!tls_cert.empty()) {
      grpc::SslServerCredentialsOptions tls;
      tls.pem_key_cert_pairs.push_back({tessera::read_file_bytes(tls_key), tessera::read_file_bytes(tls_cert)});
      credentials = grpc::SslServerCredentials(tls);
      if (auth.enabled()) credentials->SetAuthMetadataProcessor(tessera::token_gate(auth));
    }
    const auto sleep_ms = [](int ms) { return [ms] { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }; };
    if (write_delay_ms > 0) opt.before_checkpoint_rename = sleep_ms(write_delay_ms);
    if (commit_delay_ms > 0) opt.after_row_commit = sleep_ms(commit_delay_ms);
    tessera::Coordinator coordinator(opt);
    if (const uint64_t restored = coordinator.counters().jobs_restored) {
      size_t live = 0;
      for (const auto& j : coordinator.list()) live += tessera::job_live(j.state());
      spdlog::info("took up {} jobs from {} ({} to finish)", restored, opt.data_dir, live);
    }
    auth.use_credentials(&coordinator.credentials());  // enrolled workers' own
    tessera::ClientService client(coordinator, &auth);
    tessera::WorkerService worker(coordinator, &auth);
    grpc::ServerBuilder builder;
    int bound = 0;
    builder.AddListeningPort(grpc_host + ":" + std::to_string(grpc_port), credentials, &bound);
    tessera::configure_server(builder, tessera::kMaxMessageBytes, connection_limits);
    builder.RegisterService(&client);
    builder.RegisterService(&worker);
    std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
    if (!server || bound == 0) {
      spdlog::error("cannot listen on {}", listen);
      return 1;
    }
    tessera::StatusHttp status(coordinator, &auth, tls_cert, tls_key, allowed_hosts);
    const int http_bound = status.bind(http_host, http_port);
    status.start();
    std::printf("grpc listening on %s:%d%s\n", grpc_host.c_str(), bound, tls_cert.empty() ? "" : " (TLS)");
    std::printf("http listening on %s:%d%s\n", http_host.c_str(), http_bound, tls_cert.empty() ? "" : " (TLS)");
    std::unique_ptr<tessera::HttpListener> probes;
    if (health_at) {
      const auto& [health_host, health_port] = *health_at;
      probes = tessera::health_listener(coordinator);
      const int health_bound = probes->bind(health_host, health_port);
      probes->start();
      std::printf("health listening on %s:%d\n", health_host.c_str(), health_bound);
    }
    std::fflush(stdout);

    std::atomic<bool> stopping{false};
    std::thread reaper([&] {  // leases also expire when no worker is asking for work
      while (!stopping) {
        coordinator.expire_leases();
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      }
    });
    std::thread janitor([&] {  // --keep-ended: a delete may wait for a writer, so not on the reaper's tick
      const double period = std::clamp(keep_seconds / 4, 1.0, 60.0);
      for (auto next = std::chrono::steady_clock::now(); keep_seconds > 0 && !stopping;) {
        if (std::chrono::steady_clock::now() >= next) {
          for (const std::string& id : coordinator.ended_before(keep_seconds)) try {
              coordinator.remove(id);
              spdlog::info("job {}: deleted, ended over --keep-ended {} ago", id, keep_ended);
            } catch (const std::exception& e) {
              spdlog::warn("job {}: kept past --keep-ended: {}", id, e.what());
            }
          next = std::chrono::steady_clock::now() +
                 std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period));
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      }
    });
    int sig = 0;
    sigwait(&sigs, &sig);
    spdlog::info("signal {}, stopping", sig);
    tessera::stop_all_scoped_work();  // scene checks under way give up at their next step
    stopping = true;
    // Down within seconds whatever a request is doing: past kStopSeconds what is left is
    // left as a crash would leave it (a restart takes it up; a cut-short submit was never
    // acknowledged).
    constexpr int kStopSeconds = 8;
    std::promise<void> closed;
    std::future<void> closed_f = closed.get_future();
    std::thread closer([&] {
      reaper.join();
      janitor.join();
      server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
      status.stop();
      closed.set_value();
    });
    if (closed_f.wait_for(std::chrono::seconds(kStopSeconds)) != std::future_status::ready) {
      spdlog::warn("requests still running {} s after the stop signal: stopping without them", kStopSeconds);
      coordinator.checkpoint_all();
      spdlog::default_logger()->flush();
      std::fflush(nullptr);
      _exit(0);
    }
    closer.join();
    coordinator.checkpoint_all();  // results merged since the last checkpoint are kept too
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
