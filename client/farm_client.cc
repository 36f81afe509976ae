#include "client/farm_client.h"

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "client/cli_json.h"
#include "client/image_download.h"
#include "client/progress.h"
#include "core/io/files.h"
#include "core/render/frames.h"
#include "core/render/lighting.h"
#include "core/scene/load.h"
#include "core/util/text.h"
#include "rpc.h"
#include "scene_bundle.h"
#include "scene_chunks.h"
#include "wire.h"

namespace tessera {

void check(const grpc::Status& st, const FarmContext& c) {
  if (st.ok()) return;
  if (unreachable(st))
    throw FarmError("coordinator " + c.coordinator + " unreachable: " + st.error_message() +
                    tls_hint(st, !c.access.tls_ca_pem.empty()));
  throw FarmError(st.error_message());
}

std::unique_ptr<grpc::ClientContext> deadline(const FarmContext& c, double seconds) {
  return call_context(c.access, seconds);
}

namespace {

// Waits before trying a coordinator that went away again, said on stderr unless quiet.
// `then` names what comes next ("reconnecting").
void wait_to_retry(Backoff& backoff, const FarmContext& c, const grpc::Status& st, const char* lead, const char* then) {
  if (!c.quiet && !c.json)
    std::fprintf(c.err, "%stessera: lost coordinator %s (%s); %s in %.1f s\n", lead, c.coordinator.c_str(),
                 st.error_message().c_str(), then, backoff.seconds());
  backoff.wait();
}

const char* state_name(v1::JobStatus::State s) { return v1::JobStatus::State_Name(s).c_str(); }

bool ended(const v1::JobStatus& s) { return !job_live(s.state()); }

double percent_done(const v1::JobStatus& s) {
  return 100.0 * double(s.samples_done()) / double(std::max<uint64_t>(1, s.samples_total()));
}

// The files the -f paths name for a frame (#### becomes its number), or for a still.
std::vector<std::string> frame_files(const std::vector<std::string>& outputs, std::optional<int> frame) {
  std::vector<std::string> paths;
  for (const std::string& out : outputs) paths.push_back(frame ? frame_path(out, *frame) : out);
  return paths;
}

std::string describe(const v1::JobStatus& s) {
  char buf[512];
  const double percent = percent_done(s);
  if (s.frames_total() > 0)
    std::snprintf(buf, sizeof buf, "%s  %-9s %5.1f%%  frames %u/%u  tiles %u/%u  workers %u  %s", s.id().c_str(),
                  state_name(s.state()), percent, s.frames_done(), s.frames_total(), s.tiles_done(), s.tiles_total(),
                  s.active_workers(), s.name().c_str());
  else
    std::snprintf(buf, sizeof buf, "%s  %-9s %5.1f%%  passes %u/%u  tiles %u/%u  workers %u  %s", s.id().c_str(),
                  state_name(s.state()), percent, s.frame_passes_done(), s.passes_total(), s.tiles_done(),
                  s.tiles_total(), s.active_workers(), s.name().c_str());
  return buf;
}

// A sequence's frames by state, as ranges: "done 1-3,7; rendering 4 (45%); queued 5-6,8-240".
std::string describe_frames(const v1::JobStatus& s) {
  std::string out;
  for (const v1::JobStatus::State state : {v1::JobStatus::DONE, v1::JobStatus::RUNNING, v1::JobStatus::QUEUED,
                                           v1::JobStatus::CANCELLED, v1::JobStatus::FAILED}) {
    std::string list;
    for (int i = 0; i < s.frames_size();) {
      const v1::FrameStatus& f = s.frames(i);
      if (f.state() != state) {
        ++i;
        continue;
      }
      int j = i;  // a run of consecutive frame numbers in this state
      while (j + 1 < s.frames_size() && s.frames(j + 1).state() == state &&
             s.frames(j + 1).frame() == s.frames(j).frame() + 1)
        ++j;
      list += (list.empty() ? "" : ",") + std::to_string(f.frame());
      if (j > i) list += "-" + std::to_string(s.frames(j).frame());
      if (state == v1::JobStatus::RUNNING && j == i) {
        char pct[32];
        std::snprintf(pct, sizeof pct, " (%.0f%%)",
                      100.0 * double(f.samples_done()) / double(std::max<uint64_t>(1, f.samples_total())));
        list += pct;
      }
      i = j + 1;
    }
    if (list.empty()) continue;
    const char* name = state == v1::JobStatus::RUNNING  ? "rendering"
                       : state == v1::JobStatus::DONE   ? "done"
                       : state == v1::JobStatus::QUEUED ? "queued"
                       : state == v1::JobStatus::FAILED ? "failed"
                                                        : "cancelled";
    out += (out.empty() ? "" : "; ") + std::string(name) + " " + list;
  }
  return out;
}

void check_outputs(const std::vector<std::string>& outputs) {  // before the job, and the download
  try {
    prepare_outputs(outputs);
  } catch (const std::runtime_error& e) {  // (a usage error, CLI::ValidationError, goes on up: exit 2)
    if (dynamic_cast<const CLI::Error*>(&e)) throw;
    throw FarmError(e.what());
  }
}

// One image of a job (a frame's, with `frame`) to each output. With `final`, only the
// ended job's whole image is written: false (nothing written) if the coordinator serves a
// progressive one (it restarted and is rendering the job again from an earlier checkpoint).
bool fetch_one(v1::Tessera::StubInterface& stub, const std::string& job, std::optional<int> frame,
               const std::vector<std::string>& outputs, const FarmContext& c, bool final = false);

void print_status(const v1::JobStatus& s, const FarmContext& c) {
  std::fprintf(c.out, "%s\n", c.json ? cli_json(s).c_str() : describe(s).c_str());
}

// An ended job's error, if any (why it failed, what was not written), to c.err.
void print_error(const std::string& id, const v1::JobStatus& s, const FarmContext& c) {
  if (!s.error().empty()) std::fprintf(c.err, "tessera: job %s: %s\n", id.c_str(), s.error().c_str());
}

// Streams progress until the job ends; returns its final status. A lost connection (the
// coordinator restarting, a network blip) is retried with back-off for up to
// c.reconnect_seconds; only then, or when the coordinator no longer knows the job, is it
// an error.
v1::JobStatus watch(v1::Tessera::StubInterface& stub, const std::string& id, const FarmContext& c,
                    const std::function<void(const v1::JobStatus&)>& on_status = nullptr) {
  ProgressBar bar(c.quiet || c.json);
  v1::JobStatus got, last;  // last: every frame, whatever a message left out
  bool any = false;
  std::string noted;  // the live job's error as last printed (why it is stuck, a write that failed)
  Backoff backoff(Backoff::kClientFirstSeconds);
  auto lost_since = std::chrono::steady_clock::now();
  while (true) {
    grpc::ClientContext ctx;
    authorize(ctx, c.access);
    v1::JobId req;
    req.set_id(id);
    auto reader = stub.WatchJob(&ctx, req);
    while (reader->Read(&got)) {
      any = true;
      apply_watch_update(last, std::move(got));
      const v1::JobStatus& s = last;
      backoff.reset();
      if (on_status) on_status(s);
      char what[128];
      if (s.frames_total() > 0)
        std::snprintf(what, sizeof what, "%s frames %u/%u workers %u", state_name(s.state()), s.frames_done(),
                      s.frames_total(), s.active_workers());
      else
        std::snprintf(what, sizeof what, "%s passes %u/%u tiles %u/%u workers %u", state_name(s.state()),
                      s.frame_passes_done(), s.passes_total(), s.tiles_done(), s.tiles_total(), s.active_workers());
      const double fraction =
          ended(s) ? 1.0 : double(s.samples_done()) / double(std::max<uint64_t>(1, s.samples_total()));
      if (!ended(s) && s.error() != noted) {
        noted = s.error();
        if (!noted.empty()) bar.note(c.err, "job " + id + ": " + noted);
      }
      bar.update(fraction, what, s.elapsed_seconds());
      if (ended(s)) {
        ctx.TryCancel();
        return last;
      }
      lost_since = std::chrono::steady_clock::now();
    }
    const grpc::Status st = reader->Finish();
    const bool transient = st.ok() || unreachable(st) || st.error_code() == grpc::StatusCode::CANCELLED;
    if (st.error_code() == grpc::StatusCode::NOT_FOUND && any)
      throw FarmError("job " + id + " is no longer known to coordinator " + c.coordinator +
                      " (it restarted without it?): " + st.error_message());
    if (!transient) check(st, c);
    const double lost = std::chrono::duration<double>(std::chrono::steady_clock::now() - lost_since).count();
    if (lost > c.reconnect_seconds) {
      check(st, c);  // says why, naming the coordinator
      throw FarmError("lost coordinator " + c.coordinator + " while watching job " + id);
    }
    wait_to_retry(backoff, c, st, "\n", "reconnecting");  // (a new line: the progress bar is on this one)
  }
}

}  // namespace

std::unique_ptr<v1::Tessera::StubInterface> connect_coordinator(const std::string& address, const Access& access) {
  return v1::Tessera::NewStub(coordinator_channel(address, access));
}

// `tessera jobs`' table, one row per job under a header (as kubectl's): fixed widths, so
// that pages print as they come.
const char* const kJobsHeader =
    "ID                STATE      PROGRESS  FRAMES      PRIORITY  OWNER         WORKERS  SUBMITTED         ELAPSED   "
    "ETA       NAME";
// A time as the table shows it: local, to the minute ("-" when not known).
std::string table_time(const google::protobuf::Timestamp& t) {
  if (t.seconds() <= 0) return "-";
  const std::time_t when = std::time_t(t.seconds());
  std::tm local{};
  localtime_r(&when, &local);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M", &local);
  return buf;
}

std::string job_row(const v1::JobStatus& s) {
  char progress[16], frames[24], buf[512];
  std::snprintf(progress, sizeof progress, "%.1f%%", percent_done(s));
  if (s.frames_total() > 0)
    std::snprintf(frames, sizeof frames, "%u/%u", s.frames_done(), s.frames_total());
  else
    std::snprintf(frames, sizeof frames, "-");
  const bool live = s.state() == v1::JobStatus::QUEUED || s.state() == v1::JobStatus::RUNNING;
  std::snprintf(buf, sizeof buf, "%-16s  %-9s  %-8s  %-10s  %-8d  %-12s  %-7u  %-16s  %-8s  %-8s  %s", s.id().c_str(),
                state_name(s.state()), progress, frames, s.priority(), s.owner().empty() ? "-" : s.owner().c_str(),
                s.active_workers(), table_time(s.submitted_at()).c_str(), format_duration(s.elapsed_seconds()).c_str(),
                live && s.eta_seconds() > 0 ? format_duration(s.eta_seconds()).c_str() : "-", s.name().c_str());
  return buf;
}

int list_jobs(v1::Tessera::StubInterface& stub, const FarmContext& c) {
  // A page at a time (a farm keeps thousands of jobs), each printed as it comes.
  v1::ListJobsRequest req;
  req.set_page_size(kListPageSize);
  v1::JobList all;
  bool header = c.no_headers;  // printed, or not wanted
  for (;;) {
    v1::JobList page;
    check(stub.ListJobs(deadline(c).get(), req, &page), c);
    for (const auto& s : page.jobs())
      if (c.json) {
        *all.add_jobs() = s;
      } else {
        if (!header) std::fprintf(c.out, "%s\n", kJobsHeader);
        header = true;
        std::fprintf(c.out, "%s\n", job_row(s).c_str());
      }
    if (page.next_page_token().empty()) break;
    req.set_page_token(page.next_page_token());
  }
  if (c.json) std::fprintf(c.out, "%s\n", cli_json(all).c_str());
  return 0;
}

std::string resolve_job_id(v1::Tessera::StubInterface& stub, const std::string& given, const FarmContext& c) {
  constexpr size_t kIdDigits = 16;  // a job id: 64 random bits in hex
  if (given.empty() || given.size() >= kIdDigits || given.find_first_not_of("0123456789abcdef") != std::string::npos)
    return given;  // a whole id, a frame's ("ID-fN"), or not an id at all: the coordinator says
  v1::ListJobsRequest req;
  req.set_page_size(kListPageSize);
  std::vector<std::string> matches;
  for (;;) {
    v1::JobList page;
    check(stub.ListJobs(deadline(c).get(), req, &page), c);
    for (const auto& s : page.jobs())
      if (s.id().compare(0, given.size(), given) == 0) matches.push_back(s.id());
    if (page.next_page_token().empty()) break;
    req.set_page_token(page.next_page_token());
  }
  if (matches.size() == 1) return matches[0];
  if (matches.empty()) throw FarmError("no job id starts with '" + given + "'");
  std::string some;
  for (size_t i = 0; i < matches.size() && i < 3; ++i) some += (i ? ", " : "") + matches[i];
  throw FarmError("job id prefix '" + given + "' is ambiguous: " + std::to_string(matches.size()) +
                  " jobs start with it (" + some + (matches.size() > 3 ? ", ..." : "") + "); give more of it");
}

int show_status(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  if (job.empty()) return list_jobs(stub, c);
  v1::JobId req;
  req.set_id(job);
  v1::JobStatus s;
  check(stub.GetJob(deadline(c).get(), req, &s), c);
  if (c.json)
    std::fprintf(c.out, "%s\n", cli_json(s).c_str());
  else
    std::fprintf(c.out, "%s\n  elapsed %s, eta %s, %llu of %llu samples\n", describe(s).c_str(),
                 format_duration(s.elapsed_seconds()).c_str(), format_duration(s.eta_seconds()).c_str(),
                 (unsigned long long)s.samples_done(), (unsigned long long)s.samples_total());
  if (!c.json && s.frames_total() > 0) std::fprintf(c.out, "  frames: %s\n", describe_frames(s).c_str());
  if (!c.json && !s.error().empty()) std::fprintf(c.out, "  error: %s\n", s.error().c_str());
  return 0;
}

void apply_watch_update(v1::JobStatus& held, v1::JobStatus update) {
  if (!update.frames_changed_only()) {
    held = std::move(update);
    return;
  }
  google::protobuf::RepeatedPtrField<v1::FrameStatus> frames;
  frames.Swap(held.mutable_frames());
  std::map<int, int> at;  // frame number -> place
  for (int i = 0; i < frames.size(); ++i) at[frames[i].frame()] = i;
  for (v1::FrameStatus& f : *update.mutable_frames())
    if (const auto it = at.find(f.frame()); it != at.end()) frames[it->second].Swap(&f);
  update.mutable_frames()->Swap(&frames);
  update.set_frames_changed_only(false);
  held = std::move(update);
}

int watch_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  const v1::JobStatus s = watch(stub, job, c);
  print_status(s, c);
  if (!c.json) print_error(s.id(), s, c);  // (as submit --wait ends)
  return s.state() == v1::JobStatus::DONE ? 0 : 1;
}

namespace {

bool fetch_one(v1::Tessera::StubInterface& stub, const std::string& job, std::optional<int> frame,
               const std::vector<std::string>& outputs, const FarmContext& c, bool final) {
  v1::FetchImageRequest req;
  req.set_id(job);
  if (frame) req.set_frame(*frame);
  const std::vector<std::string> paths = frame_files(outputs, frame);
  // A lost connection (the coordinator restarting just as the job ended) is retried with
  // back-off for up to c.reconnect_seconds since the last piece came, as watching is,
  // resuming where it was cut (a stream's own 600 s deadline only makes it resume).
  Backoff backoff(Backoff::kClientFirstSeconds);
  auto since = std::chrono::steady_clock::now();
  try {
    const ImageDownload got = download_image(
        req, paths, final,
        [&](grpc::ClientContext* ctx, const v1::FetchImageRequest& r) { return stub.FetchImageChunks(ctx, r); },
        [&] { return deadline(c, 600); },
        [&](const grpc::Status& st, bool progressed) {
          if (progressed) {  // the window counts from the last piece, not the fetch's start
            since = std::chrono::steady_clock::now();
            backoff = Backoff(Backoff::kClientFirstSeconds);
          }
          if (!unreachable(st) ||
              std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count() > c.reconnect_seconds) {
            check(st, c);
            return false;
          }
          wait_to_retry(backoff, c, st, "", "fetching again");
          return true;
        });
    return !final || got.final;
  } catch (const std::runtime_error& e) {
    throw FarmError(e.what());
  }
}

}  // namespace

int fetch_image(v1::Tessera::StubInterface& stub, const std::string& job, const std::vector<std::string>& outputs,
                const FarmContext& c, const FetchWhat& what) {
  check_outputs(outputs);
  if (what.all && what.frame) throw FarmError("give --frame N or --all, not both");
  // --json: what was written, as one object (numbers as numbers).
  auto files_of = [&](std::optional<int> frame) { return nlohmann::json(frame_files(outputs, frame)); };
  if (!what.all) {
    fetch_one(stub, job, what.frame, outputs, c);
    if (c.json)
      std::fprintf(c.out, "%s\n",
                   nlohmann::json{{"job", job},
                                  {"frame", what.frame ? nlohmann::json(*what.frame) : nlohmann::json(nullptr)},
                                  {"files", files_of(what.frame)}}
                       .dump()
                       .c_str());
    return 0;
  }
  v1::JobId req;
  req.set_id(job);
  v1::JobStatus s;
  check(stub.GetJob(deadline(c).get(), req, &s), c);
  if (s.frames_total() == 0) throw FarmError("job " + job + " is not a sequence: fetch it without --all");
  if (s.frames_size() > 1)
    for (const std::string& out : outputs)
      if (out.find('#') == std::string::npos)
        throw FarmError("--all: several frames need a #### in every -f path (got '" + out + "')");
  int written = 0;
  nlohmann::json frames = nlohmann::json::array();
  for (const v1::FrameStatus& f : s.frames())
    if (f.state() == v1::JobStatus::DONE && fetch_one(stub, job, f.frame(), outputs, c, true)) {
      ++written;
      frames.push_back({{"frame", f.frame()}, {"files", files_of(f.frame())}});
    }
  if (c.json)
    std::fprintf(c.out, "%s\n",
                 nlohmann::json{{"job", job}, {"frames_total", s.frames_size()}, {"written", frames}}.dump().c_str());
  else
    std::fprintf(c.err, "%d of %d frames finished and written%s\n", written, s.frames_size(),
                 written < s.frames_size() ? (" (the others: " + describe_frames(s) + ")").c_str() : "");
  return 0;
}

int cancel_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  v1::JobId req;
  req.set_id(job);
  v1::JobStatus s;
  check(stub.CancelJob(deadline(c).get(), req, &s), c);
  print_status(s, c);
  return 0;
}

int requeue_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  v1::JobId req;
  req.set_id(job);
  v1::JobStatus s;
  check(stub.RequeueJob(deadline(c, 120).get(), req, &s), c);  // (reads its films back from disk)
  print_status(s, c);
  return 0;
}

int set_job_priority(v1::Tessera::StubInterface& stub, const std::string& job, int priority, const FarmContext& c) {
  v1::SetPriorityRequest req;
  req.set_id(job);
  req.set_priority(priority);
  v1::JobStatus s;
  check(stub.SetJobPriority(deadline(c).get(), req, &s), c);
  print_status(s, c);
  return 0;
}

int delete_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  v1::JobId req;
  req.set_id(job);
  v1::DeleteJobResponse r;
  check(stub.DeleteJob(deadline(c, 300).get(), req, &r), c);  // (waits for a write under way to stop)
  if (c.json)
    std::fprintf(c.out, "%s\n", cli_json(r).c_str());
  else
    std::fprintf(c.out, "job %s deleted (%.1f MB freed)\n", r.id().c_str(), double(r.bytes_freed()) / 1e6);
  return 0;
}

namespace {

// A job's name where the user gave none: the scene's path, or its file name where the
// path is longer than the coordinator takes (kMaxJobNameBytes).
std::string default_job_name(const std::string& scene) {
  if (scene.size() <= kMaxJobNameBytes) return scene;
  return utf8_prefix(std::filesystem::path(scene).filename().string(), kMaxJobNameBytes);
}

// Sends the scene in pieces (UploadScene) and returns the upload's id, for SubmitJob. The
// coordinator out of reach (restarting, a network blip) is retried with back-off for up to
// c.reconnect_seconds: an upload is only bytes until a submit names it, so sending it again
// is harmless.
std::string upload_scene(v1::Tessera::StubInterface& stub, const SceneSource& scene, const FarmContext& c) {
  uint64_t bytes = 0;
  for (const v1::SceneFileInfo& f : scene.manifest.files()) bytes += f.size();
  Backoff backoff(Backoff::kClientFirstSeconds);
  for (const auto since = std::chrono::steady_clock::now();;) {
    const auto ctx = deadline(c, 120 + double(bytes) / (1 << 20));  // two minutes, then 1 MiB/s at least
    v1::SceneUpload upload;
    const auto writer = stub.UploadScene(ctx.get(), &upload);
    v1::SceneChunk first;
    *first.mutable_manifest() = scene.manifest;
    bool sent = writer->Write(first);
    try {
      sent = sent &&
             send_pieces(scene, 0, 0, c.scene_chunk_bytes, [&](v1::SceneChunk& piece) { return writer->Write(piece); });
    } catch (const std::exception& e) {  // a file that can no longer be read
      ctx->TryCancel();
      writer->Finish();
      throw FarmError(e.what());
    }
    if (sent) writer->WritesDone();
    const grpc::Status st = writer->Finish();
    if (st.ok()) return upload.upload_id();
    if (!unreachable(st) ||
        std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count() > c.reconnect_seconds)
      check(st, c);
    wait_to_retry(backoff, c, st, "", "sending the scene again");
  }
}

int report_submitted(const std::string& id, const v1::JobStatus& final, const std::vector<std::string>& outputs,
                     const FarmContext& c) {
  if (c.json) {
    std::fprintf(c.out, "%s\n", cli_json(final).c_str());
  } else {
    std::fprintf(c.out, "%s: %s in %.2f s, %llu samples -> ", id.c_str(), state_name(final.state()),
                 final.elapsed_seconds(), (unsigned long long) final.samples_done());
    for (size_t i = 0; i < outputs.size(); ++i) std::fprintf(c.out, "%s%s", i ? ", " : "", outputs[i].c_str());
    std::fprintf(c.out, "\n");
  }
  print_error(id, final, c);
  return final.state() == v1::JobStatus::DONE ? 0 : 1;
}

}  // namespace

int submit_job(v1::Tessera::StubInterface& stub, const SubmitRequest& r, const FarmContext& c) {
  v1::SubmitJobRequest req;
  req.set_version(kProtocolVersion);
  RenderSettings settings = to_settings(r.flags);
  const std::vector<int> frames = sequence_frames(r.flags);
  for (const int f : frames) req.add_frames(f);
  const auto outputs = output_paths(r.flags);
  if (r.wait) check_outputs(outputs);
  SceneSource scene;
  try {
    // Loaded here too, as tessera render loads it: a bad scene is refused before its upload,
    // and the user sees its warnings and lighting as a local render shows them.
    print_scene_notes(load_scene(r.flags.scene), settings, c.err);
    auto files = scene_bundle_files(r.flags.scene);
    if (!settings.environment_map.empty()) {
      // The environment map travels in the bundle, named apart from the scene's own files;
      // workers find it relative to the main file.
      files.emplace_back(".tessera-env/" + std::filesystem::path(settings.environment_map).filename().string(),
                         settings.environment_map);
      settings.environment_map = files.back().first;
    }
    scene = scene_source(files[0].first, files);
  } catch (const std::exception& e) {
    throw FarmError(e.what());
  }
  *req.mutable_settings() = to_proto(settings);
  req.set_upload_id(upload_scene(stub, scene, c));
  req.set_priority(r.priority);
  req.set_name(r.name.empty() ? default_job_name(r.flags.scene) : r.name);
  v1::JobId id;
  check(stub.SubmitJob(deadline(c, 120).get(), req, &id), c);
  if (!r.wait) {
    if (c.json)
      std::fprintf(c.out, "{\"id\": \"%s\"}\n", id.id().c_str());
    else
      std::fprintf(c.out, "%s\n", id.id().c_str());
    return 0;
  }
  if (!c.json) std::fprintf(c.err, "job %s submitted\n", id.id().c_str());
  // Only final images are written. One that is not (the coordinator restarted after
  // saying the job ended, and renders it again from an earlier checkpoint) is fetched
  // again once the job has ended again.
  if (frames.empty()) {
    while (true) {
      const v1::JobStatus final = watch(stub, id.id(), c);
      if (fetch_one(stub, id.id(), std::nullopt, outputs, c, true)) return report_submitted(id.id(), final, outputs, c);
    }
  }
  // A sequence: each frame's files are written as soon as the frame is done.
  std::set<int> written;
  auto write_done = [&](const v1::JobStatus& s) {
    bool all = true;  // every DONE frame written
    for (const v1::FrameStatus& f : s.frames())
      if (f.state() == v1::JobStatus::DONE && !written.count(f.frame())) {
        if (fetch_one(stub, id.id(), f.frame(), outputs, c, true))
          written.insert(f.frame());
        else
          all = false;
      }
    return all;
  };
  v1::JobStatus final;
  std::string said;  // the last write error shown: each said once, while the frames go on
  do {
    final = watch(stub, id.id(), c, [&](const v1::JobStatus& s) {
      try {
        write_done(s);
      } catch (const FarmError& e) {  // (a coordinator restarting, say) fetched again at the end
        if (e.what() != said && !c.json)
          std::fprintf(c.err, "a finished frame was not written yet (tried again at the end): %s\n", e.what());
        said = e.what();
      }
    });
  } while (!write_done(final));
  std::vector<std::string> patterns;
  for (const std::string& out : outputs)
    patterns.push_back(out + " (" + std::to_string(written.size()) + " of " + std::to_string(frames.size()) +
                       " frames)");
  return report_submitted(id.id(), final, patterns, c);
}

}  // namespace tessera
