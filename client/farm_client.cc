#include "client/farm_client.h"

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <thread>

#include "client/progress.h"
#include "core/io/files.h"
#include "scene_bundle.h"
#include "wire.h"

namespace tessera {
namespace {

void check(const grpc::Status& st, const FarmContext& c) {
  if (st.ok()) return;
  if (st.error_code() == grpc::StatusCode::UNAVAILABLE || st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)
    throw FarmError("coordinator " + c.coordinator + " unreachable: " + st.error_message());
  throw FarmError(st.error_message());
}

std::unique_ptr<grpc::ClientContext> deadline(const FarmContext& c, double seconds = 30) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  authorize(*ctx, c.access);
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000)));
  return ctx;
}

const char* state_name(v1::JobStatus::State s) { return v1::JobStatus::State_Name(s).c_str(); }

bool ended(const v1::JobStatus& s) { return s.state() != v1::JobStatus::QUEUED && s.state() != v1::JobStatus::RUNNING; }

std::string describe(const v1::JobStatus& s) {
  char buf[256];
  std::snprintf(
      buf, sizeof buf, "%s  %-9s %5.1f%%  passes %u/%u  tiles %u/%u  workers %u  %s", s.id().c_str(),
      state_name(s.state()), 100.0 * double(s.samples_done()) / double(std::max<uint64_t>(1, s.samples_total())),
      s.frame_passes_done(), s.passes_total(), s.tiles_done(), s.tiles_total(), s.active_workers(), s.name().c_str());
  return buf;
}

void print_status(const v1::JobStatus& s, const FarmContext& c) {
  std::fprintf(c.out, "%s\n", c.json ? proto_json(s).c_str() : describe(s).c_str());
}

// Streams progress until the job ends; returns its final status. A lost connection (the
// coordinator restarting, a network blip) is retried with back-off for up to
// c.reconnect_seconds; only then, or when the coordinator no longer knows the job, is it
// an error.
v1::JobStatus watch(v1::Tessera::StubInterface& stub, const std::string& id, const FarmContext& c) {
  ProgressBar bar(c.quiet || c.json);
  v1::JobStatus s, last;
  bool any = false;
  double backoff = 0.25;
  auto lost_since = std::chrono::steady_clock::now();
  while (true) {
    grpc::ClientContext ctx;
    authorize(ctx, c.access);
    v1::JobId req;
    req.set_id(id);
    auto reader = stub.WatchJob(&ctx, req);
    while (reader->Read(&s)) {
      any = true;
      last = s;
      backoff = 0.25;
      char what[128];
      std::snprintf(what, sizeof what, "%s passes %u/%u tiles %u/%u workers %u", state_name(s.state()),
                    s.frame_passes_done(), s.passes_total(), s.tiles_done(), s.tiles_total(), s.active_workers());
      const double fraction =
          ended(s) ? 1.0 : double(s.samples_done()) / double(std::max<uint64_t>(1, s.samples_total()));
      bar.update(fraction, what, s.elapsed_seconds());
      if (ended(s)) {
        ctx.TryCancel();
        return last;
      }
      lost_since = std::chrono::steady_clock::now();
    }
    const grpc::Status st = reader->Finish();
    const bool transient = st.ok() || st.error_code() == grpc::StatusCode::UNAVAILABLE ||
                           st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED ||
                           st.error_code() == grpc::StatusCode::CANCELLED;
    if (st.error_code() == grpc::StatusCode::NOT_FOUND && any)
      throw FarmError("job " + id + " is no longer known to coordinator " + c.coordinator +
                      " (it restarted without it?): " + st.error_message());
    if (!transient) check(st, c);
    const double lost = std::chrono::duration<double>(std::chrono::steady_clock::now() - lost_since).count();
    if (lost > c.reconnect_seconds) {
      check(st, c);  // says why, naming the coordinator
      throw FarmError("lost coordinator " + c.coordinator + " while watching job " + id);
    }
    if (!c.quiet && !c.json)
      std::fprintf(c.err, "\ntessera: lost coordinator %s (%s); reconnecting in %.1f s\n", c.coordinator.c_str(),
                   st.error_message().c_str(), backoff);
    std::this_thread::sleep_for(std::chrono::duration<double>(backoff));
    backoff = std::min(5.0, backoff * 2);
  }
}

}  // namespace

std::unique_ptr<v1::Tessera::StubInterface> connect_coordinator(const std::string& address, const Access& access) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  return v1::Tessera::NewStub(grpc::CreateCustomChannel(address, channel_credentials(access), args));
}

int list_jobs(v1::Tessera::StubInterface& stub, const FarmContext& c) {
  v1::JobList list;
  check(stub.ListJobs(deadline(c).get(), v1::ListJobsRequest(), &list), c);
  if (c.json)
    std::fprintf(c.out, "%s\n", proto_json(list).c_str());
  else
    for (const auto& s : list.jobs()) std::fprintf(c.out, "%s\n", describe(s).c_str());
  return 0;
}

int show_status(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  if (job.empty()) return list_jobs(stub, c);
  v1::JobId req;
  req.set_id(job);
  v1::JobStatus s;
  check(stub.GetJob(deadline(c).get(), req, &s), c);
  if (c.json)
    std::fprintf(c.out, "%s\n", proto_json(s).c_str());
  else
    std::fprintf(c.out, "%s\n  elapsed %s, eta %s, %llu of %llu samples\n", describe(s).c_str(),
                 format_duration(s.elapsed_seconds()).c_str(), format_duration(s.eta_seconds()).c_str(),
                 (unsigned long long)s.samples_done(), (unsigned long long)s.samples_total());
  if (!c.json && !s.error().empty()) std::fprintf(c.out, "  error: %s\n", s.error().c_str());
  return 0;
}

int watch_job(v1::Tessera::StubInterface& stub, const std::string& job, const FarmContext& c) {
  const v1::JobStatus s = watch(stub, job, c);
  print_status(s, c);
  return s.state() == v1::JobStatus::DONE ? 0 : 1;
}

int fetch_image(v1::Tessera::StubInterface& stub, const std::string& job, const std::vector<std::string>& outputs,
                const FarmContext& c) {
  auto has_ext = [](const std::string& p, const char* ext) {
    return p.size() >= 4 && p.compare(p.size() - 4, 4, ext) == 0;
  };
  for (const std::string& out : outputs)  // before the download, which may be large
    if (!has_ext(out, ".exr") && !has_ext(out, ".png"))
      throw FarmError(out + ": unknown image format (use .exr or .png)");
  v1::FetchImageRequest req;
  req.set_id(job);
  for (const std::string& out : outputs) {  // only the formats written: a PNG is encoded on request
    if (has_ext(out, ".exr")) req.set_exr(true);
    if (has_ext(out, ".png")) req.set_png(true);
  }
  v1::Image img;
  check(stub.FetchImage(deadline(c, 120).get(), req, &img), c);
  for (const std::string& out : outputs) {
    try {
      write_file_atomic(out, has_ext(out, ".exr") ? img.exr() : img.png());
    } catch (const std::runtime_error& e) {
      throw FarmError(e.what());
    }
  }
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

int submit_job(v1::Tessera::StubInterface& stub, const SubmitRequest& r, const FarmContext& c) {
  v1::SubmitJobRequest req;
  req.set_version(kProtocolVersion);
  *req.mutable_settings() = to_proto(to_settings(r.flags));
  std::string main;
  try {
    pack_scene(r.flags.scene, &main, req.mutable_files());
  } catch (const std::exception& e) {
    throw FarmError(e.what());
  }
  req.set_main_file(main);
  req.set_priority(r.priority);
  req.set_name(r.name.empty() ? r.flags.scene : r.name);
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
  const v1::JobStatus final = watch(stub, id.id(), c);
  const auto outputs = output_paths(r.flags);
  fetch_image(stub, id.id(), outputs, c);
  if (c.json) {
    std::fprintf(c.out, "%s\n", proto_json(final).c_str());
  } else {
    std::fprintf(c.out, "%s: %s in %.2f s, %llu samples -> ", id.id().c_str(), state_name(final.state()),
                 final.elapsed_seconds(), (unsigned long long) final.samples_done());
    for (size_t i = 0; i < outputs.size(); ++i) std::fprintf(c.out, "%s%s", i ? ", " : "", outputs[i].c_str());
    std::fprintf(c.out, "\n");
  }
  if (!final.error().empty()) std::fprintf(c.err, "tessera: job %s: %s\n", id.id().c_str(), final.error().c_str());
  return final.state() == v1::JobStatus::DONE ? 0 : 1;
}

}  // namespace tessera
