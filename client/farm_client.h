// The farm subcommands (`submit`, `status`, `jobs`, `watch`, `fetch`, `cancel`, `requeue`,
// `priority`, `delete`; `events` in events_command.h) as one
// function each over a coordinator stub: farm_commands.cc binds them to flags, tests call
// them against an in-process coordinator. Each returns the process exit code and throws
// FarmError for what the user must be told (an unreachable coordinator, a refused job).
#pragma once

#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "access.h"
#include "client/render_flags.h"
#include "tessera.grpc.pb.h"

namespace tessera {

class FarmError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FarmContext {
  std::string coordinator = "127.0.0.1:7878";  // for messages; the stub is already connected
  bool json = false;                           // machine-readable output
  bool quiet = false;                          // no progress bar
  std::FILE* out = stdout;
  std::FILE* err = stderr;
  Access access;  // the token sent with every call, and TLS
  // How long watching a job (watch, submit --wait) keeps reconnecting to a coordinator
  // that went away before giving up.
  double reconnect_seconds = 300;
  bool no_headers = false;  // `tessera jobs`: rows only (kubectl's --no-headers)
  // A scene is sent in pieces of at most this many bytes (tests send small ones).
  size_t scene_chunk_bytes = size_t(1) << 20;
};

// Throws FarmError saying why a call failed (an unreachable coordinator named, with a hint
// when TLS is the likely cause).
void check(const grpc::Status& st, const FarmContext& c);
// A call's context: the access token, and a deadline `seconds` away.
std::unique_ptr<grpc::ClientContext> deadline(const FarmContext& c, double seconds = 30);

std::unique_ptr<v1::Tessera::StubInterface> connect_coordinator(const std::string& address,
                                                                const Access& access = Access());

// A job named by a prefix of its id, as git and docker take them: the one job whose id
// starts with it. A whole id (16 hex digits), a frame's id or an empty one is returned as
// it is. Throws FarmError for a prefix no job or several jobs have (naming some).
std::string resolve_job_id(v1::Tessera::StubInterface& stub, const std::string& given, const FarmContext& c);

struct SubmitRequest {
  RenderFlags flags;
  int priority = 0;
  std::string name;
  bool wait = false;  // show progress until the job ends, then download the image to -f
};
int submit_job(v1::Tessera::StubInterface& stub, const SubmitRequest& request, const FarmContext& c);
// One job with its times, or every job when `job` is empty.
int show_status(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c);
int list_jobs(v1::Tessera::StubInterface& stub, const FarmContext& c);
// Shows progress until the job ends; exit code 0 when it is DONE.
int watch_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c);
// A WatchJob message onto the status a watcher holds: a whole one replaces it; one with
// frames_changed_only replaces the frames it names (by number) and keeps the others.
void apply_watch_update(v1::JobStatus& held, v1::JobStatus update);
// Which image of a job to fetch: its only one, one frame of a sequence, or every finished
// frame (to -f paths with ####, as frame_path fills them in).
struct FetchWhat {
  std::optional<int> frame;
  bool all = false;
};
// The job's latest image, to each output (.exr or .png), written atomically.
int fetch_image(v1::Tessera::StubInterface& stub, const std::string& job, const std::vector<std::string>& outputs,
                const FarmContext& c, const FetchWhat& what = {});
int cancel_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c);
// A FAILED or CANCELLED job (a sequence: its frames not DONE) goes on from its checkpoints.
int requeue_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c);
int set_job_priority(v1::Tessera::StubInterface& stub, const std::string& job, int priority, const FarmContext& c);
// The job and everything it left on the coordinator's disk (a live one is cancelled first).
int delete_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c);
// `jobs` asks for this many jobs a call.
constexpr uint32_t kListPageSize = 500;

}  // namespace tessera
