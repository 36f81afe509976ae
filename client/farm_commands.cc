#include "client/farm_commands.h"

#include <memory>

#include "client/events_command.h"
#include "client/farm_client.h"
#include "core/util/cli.h"

namespace tessera {

std::vector<std::function<int()>> add_farm_commands(CLI::App& app) {
  std::vector<std::function<int()>> runs;
  // Every command: --coordinator and --json, then one function of farm_client.h.
  auto add = [&](const char* name, const char* help, auto&& bind, auto&& run) {
    auto c = std::make_shared<FarmContext>();
    CLI::App* cmd = app.add_subcommand(name, help);
    bind(cmd, *c);
    cmd->add_option("--coordinator", c->coordinator, "coordinator gRPC address HOST:PORT (else $TESSERA_COORDINATOR)")
        ->envname("TESSERA_COORDINATOR")
        ->capture_default_str();
    cmd->add_flag("--json", c->json, "machine-readable output");
    auto token_file = std::make_shared<std::string>(), tls_ca = std::make_shared<std::string>();
    cmd->add_option("--token-file", *token_file,
                    "file holding the access token (else $TESSERA_TOKEN_FILE, or the token in $TESSERA_TOKEN)");
    cmd->add_option("--tls-ca", *tls_ca, "PEM certificate authority: connect over TLS (else $TESSERA_TLS_CA)");
    cmd->add_option("--reconnect-seconds", c->reconnect_seconds,
                    "while watching a job, keep reconnecting to a coordinator that went away this long")
        ->capture_default_str()
        ->check(finite_range(0.0, 1e6));
    runs.push_back([cmd, c, run, token_file, tls_ca]() -> int {
      if (!cmd->parsed()) return -1;
      try {
        try {
          c->access = load_access(*token_file, *tls_ca);
        } catch (const std::runtime_error& e) {
          throw FarmError(e.what());
        }
        return run(*connect_coordinator(c->coordinator, c->access), *c);
      } catch (const FarmError& e) {
        std::fprintf(stderr, "tessera: error: %s\n", e.what());
        return 1;
      }
    });
  };
  auto job = std::make_shared<std::string>();
  auto job_arg = [job](bool required) {
    return [job, required](CLI::App* cmd, FarmContext&) {
      CLI::Option* o = cmd->add_option("job", *job, "job id, or the start of one that no other job's has");
      if (required) o->required();
    };
  };

  auto submit = std::make_shared<SubmitRequest>();
  add(
      "submit", "Submit a render job to a coordinator",
      [submit](CLI::App* cmd, FarmContext& c) {
        add_render_flags(cmd, submit->flags);
        cmd->add_flag("--wait", submit->wait, "show progress until the job ends, then download the image (-f)");
        cmd->add_option("--priority", submit->priority, "higher runs first")->capture_default_str();
        cmd->add_option("--name", submit->name, "job name shown in listings");
        cmd->add_flag("-q,--quiet", c.quiet, "no progress output");
      },
      [submit](v1::Tessera::StubInterface& stub, const FarmContext& c) { return submit_job(stub, *submit, c); });
  add("status", "Show one job, or every job", job_arg(false),
      [job](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return show_status(stub, resolve_job_id(stub, *job, c), c);
      });
  add(
      "jobs", "List jobs (a table under a header; --no-headers: rows only)",
      [](CLI::App* cmd, FarmContext& c) { cmd->add_flag("--no-headers", c.no_headers, "rows only, for scripts"); },
      [](v1::Tessera::StubInterface& stub, const FarmContext& c) { return list_jobs(stub, c); });
  add("watch", "Show a job's progress until it ends", job_arg(true),
      [job](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return watch_job(stub, resolve_job_id(stub, *job, c), c);
      });
  auto outputs = std::make_shared<std::vector<std::string>>();
  auto which = std::make_shared<FetchWhat>();
  add(
      "fetch", "Download a job's latest image (a sequence's: --frame N, or --all finished frames)",
      [job_arg, outputs, which](CLI::App* cmd, FarmContext& c) {
        job_arg(true)(cmd, c);
        cmd->add_option("-f", *outputs, "output .exr or .png (repeat for both; #### becomes the frame number)")
            ->required();
        cmd->add_option("--frame", which->frame, "the frame of a sequence");
        cmd->add_flag("--all", which->all, "every finished frame of a sequence (-f paths need ####)");
      },
      [job, outputs, which](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return fetch_image(stub, resolve_job_id(stub, *job, c), *outputs, c, *which);
      });
  add("cancel", "Cancel a job (what was rendered is kept)", job_arg(true),
      [job](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return cancel_job(stub, resolve_job_id(stub, *job, c), c);
      });
  add("requeue", "Take a FAILED or CANCELLED job up again from what it rendered (a sequence: its unfinished frames)",
      job_arg(true), [job](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return requeue_job(stub, resolve_job_id(stub, *job, c), c);
      });
  auto priority = std::make_shared<int>(0);
  add(
      "priority", "Change a job's priority (higher runs first)",
      [job_arg, priority](CLI::App* cmd, FarmContext& c) {
        job_arg(true)(cmd, c);
        cmd->add_option("priority", *priority, "the new priority")->required();
      },
      [job, priority](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return set_job_priority(stub, resolve_job_id(stub, *job, c), *priority, c);
      });
  add("delete",
      "Delete a job: its record, images, checkpoints, and scene if no other job uses it (a live job is "
      "cancelled first)",
      job_arg(true), [job](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        return delete_job(stub, resolve_job_id(stub, *job, c), c);
      });
  auto events = std::make_shared<EventsRequest>();
  add(
      "events",
      "What happened on the farm, newest last: jobs submitted, started, ended (and why), cancelled, requeued, "
      "deleted; workers registered, lost, quarantined; who did it",
      [job_arg, events](CLI::App* cmd, FarmContext& c) {
        job_arg(false)(cmd, c);
        cmd->add_option("--tail", events->tail, "the newest this many (at most 1000)")
            ->capture_default_str()
            ->check(CLI::Range(1, 1000));
        cmd->add_flag("--follow", events->follow, "then print new events as they come, until interrupted");
        cmd->add_flag("--no-headers", c.no_headers, "rows only, for scripts");
      },
      [job, events](v1::Tessera::StubInterface& stub, const FarmContext& c) {
        EventsRequest r = *events;
        if (!job->empty()) r.job = resolve_job_id(stub, *job, c);
        return list_events(stub, r, c);
      });
  return runs;
}

}  // namespace tessera
