#include "client/farm_commands.h"

#include <grpcpp/grpcpp.h>

#include <fstream>
#include <memory>

#include "client/progress.h"
#include "client/render_flags.h"
#include "wire.h"

namespace tessera {
namespace {

struct FarmArgs {
  std::string coordinator = "127.0.0.1:7878";
  bool json = false;
  bool quiet = false;
};

class FarmError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

std::unique_ptr<v1::Tessera::Stub> connect(const FarmArgs& a) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  return v1::Tessera::NewStub(grpc::CreateCustomChannel(a.coordinator, grpc::InsecureChannelCredentials(), args));
}

void check(const grpc::Status& st, const FarmArgs& a) {
  if (st.ok()) return;
  if (st.error_code() == grpc::StatusCode::UNAVAILABLE || st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)
    throw FarmError("coordinator " + a.coordinator + " unreachable: " + st.error_message());
  throw FarmError(st.error_message());
}

std::unique_ptr<grpc::ClientContext> ctx(double seconds = 30) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000)));
  return c;
}

std::string json_of(const google::protobuf::Message& m) { return proto_json(m); }

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

// Every job, as JSON or one line each (`tessera jobs`, `tessera status`).
int list_jobs(const FarmArgs& a) {
  v1::JobList list;
  check(connect(a)->ListJobs(ctx().get(), v1::ListJobsRequest(), &list), a);
  if (a.json)
    std::printf("%s\n", json_of(list).c_str());
  else
    for (const auto& s : list.jobs()) std::printf("%s\n", describe(s).c_str());
  return 0;
}

void print_status(const v1::JobStatus& s, const FarmArgs& a) {
  if (a.json)
    std::printf("%s\n", json_of(s).c_str());
  else
    std::printf("%s\n", describe(s).c_str());
}

// Streams progress until the job ends; returns its final status.
v1::JobStatus watch(v1::Tessera::Stub& stub, const std::string& id, const FarmArgs& a) {
  grpc::ClientContext c;
  v1::JobId req;
  req.set_id(id);
  auto reader = stub.WatchJob(&c, req);
  v1::JobStatus s, last;
  ProgressBar bar(a.quiet || a.json);
  bool any = false;
  while (reader->Read(&s)) {
    any = true;
    last = s;
    char what[128];
    std::snprintf(what, sizeof what, "%s passes %u/%u tiles %u/%u workers %u", state_name(s.state()),
                  s.frame_passes_done(), s.passes_total(), s.tiles_done(), s.tiles_total(), s.active_workers());
    const double fraction =
        ended(s) ? 1.0 : double(s.samples_done()) / double(std::max<uint64_t>(1, s.samples_total()));
    bar.update(fraction, what, s.elapsed_seconds());
    if (ended(s)) break;
  }
  const grpc::Status st = reader->Finish();
  if (!any) check(st, a);
  if (!ended(last)) throw FarmError("lost the coordinator while watching job " + id);
  return last;
}

void fetch(v1::Tessera::Stub& stub, const std::string& id, const std::vector<std::string>& outputs, const FarmArgs& a) {
  v1::FetchImageRequest req;
  req.set_id(id);
  v1::Image img;
  check(stub.FetchImage(ctx(120).get(), req, &img), a);
  for (const std::string& out : outputs) {
    const bool exr = out.size() >= 4 && out.compare(out.size() - 4, 4, ".exr") == 0;
    const bool png = out.size() >= 4 && out.compare(out.size() - 4, 4, ".png") == 0;
    if (!exr && !png) throw FarmError(out + ": unknown image format (use .exr or .png)");
    const std::string& bytes = exr ? img.exr() : img.png();
    const std::string tmp = out + ".tmp";
    {
      std::ofstream f(tmp, std::ios::binary);
      f.write(bytes.data(), std::streamsize(bytes.size()));
      if (!f) throw FarmError(out + ": cannot write");
    }
    if (std::rename(tmp.c_str(), out.c_str()) != 0) throw FarmError(out + ": cannot write");
  }
}

}  // namespace

std::vector<std::function<int()>> add_farm_commands(CLI::App& app) {
  std::vector<std::function<int()>> runs;
  auto common = [](CLI::App* cmd, FarmArgs& a) {
    cmd->add_option("--coordinator", a.coordinator, "coordinator gRPC address HOST:PORT")->capture_default_str();
    cmd->add_flag("--json", a.json, "machine-readable output");
  };
  auto guard = [](auto f) {
    return [f]() -> int {
      try {
        return f();
      } catch (const FarmError& e) {
        std::fprintf(stderr, "tessera: error: %s\n", e.what());
        return 1;
      }
    };
  };

  {  // submit
    struct Args {
      FarmArgs farm;
      RenderFlags flags;
      bool wait = false;
      int priority = 0;
      double noise_target = 0;
      uint32_t tile = 0;
      std::string name;
    };
    auto a = std::make_shared<Args>();
    CLI::App* cmd = app.add_subcommand("submit", "Submit a render job to a coordinator");
    add_render_flags(cmd, a->flags);
    common(cmd, a->farm);
    cmd->add_flag("--wait", a->wait, "show progress until the job ends, then download the image (-f)");
    cmd->add_option("--priority", a->priority, "higher runs first")->capture_default_str();
    cmd->add_option("--noise-target", a->noise_target, "stop refining tiles whose relative error is below this")
        ->check(CLI::Range(0.0, 1e9));
    cmd->add_option("--tile", a->tile, "tile size (default: the coordinator's)")->check(CLI::Range(1, 4096));
    cmd->add_option("--name", a->name, "job name shown in listings");
    cmd->add_flag("-q,--quiet", a->farm.quiet, "no progress output");
    runs.push_back(guard([a, cmd]() -> int {
      if (!cmd->parsed()) return -1;
      v1::SubmitJobRequest req;
      req.set_version(kProtocolVersion);
      std::string main;
      try {
        pack_scene(a->flags.scene, &main, req.mutable_files());
      } catch (const std::exception& e) {
        throw FarmError(e.what());
      }
      req.set_main_file(main);
      *req.mutable_settings() = to_proto(to_settings(a->flags));
      req.set_tile_size(a->tile);
      req.set_priority(a->priority);
      req.set_noise_target(a->noise_target);
      req.set_name(a->name.empty() ? a->flags.scene : a->name);
      auto stub = connect(a->farm);
      v1::JobId id;
      check(stub->SubmitJob(ctx(120).get(), req, &id), a->farm);
      if (!a->wait) {
        if (a->farm.json)
          std::printf("{\"id\": \"%s\"}\n", id.id().c_str());
        else
          std::printf("%s\n", id.id().c_str());
        return 0;
      }
      if (!a->farm.json) std::fprintf(stderr, "job %s submitted\n", id.id().c_str());
      const v1::JobStatus final = watch(*stub, id.id(), a->farm);
      const auto outputs = output_paths(a->flags);
      fetch(*stub, id.id(), outputs, a->farm);
      if (a->farm.json) {
        std::printf("%s\n", json_of(final).c_str());
      } else {
        std::printf("%s: %s in %.2f s, %llu samples -> ", id.id().c_str(), state_name(final.state()),
                    final.elapsed_seconds(), (unsigned long long) final.samples_done());
        for (size_t i = 0; i < outputs.size(); ++i) std::printf("%s%s", i ? ", " : "", outputs[i].c_str());
        std::printf("\n");
      }
      return final.state() == v1::JobStatus::DONE ? 0 : 1;
    }));
  }
  {  // status [JOB]
    auto a = std::make_shared<FarmArgs>();
    auto job = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand("status", "Show one job, or every job");
    cmd->add_option("job", *job, "job id");
    common(cmd, *a);
    runs.push_back(guard([a, job, cmd]() -> int {
      if (!cmd->parsed()) return -1;
      if (job->empty()) return list_jobs(*a);
      v1::JobId req;
      req.set_id(*job);
      v1::JobStatus s;
      check(connect(*a)->GetJob(ctx().get(), req, &s), *a);
      if (a->json)
        std::printf("%s\n", json_of(s).c_str());
      else
        std::printf("%s\n  elapsed %s, eta %s, %llu of %llu samples\n", describe(s).c_str(),
                    format_duration(s.elapsed_seconds()).c_str(), format_duration(s.eta_seconds()).c_str(),
                    (unsigned long long)s.samples_done(), (unsigned long long)s.samples_total());
      return 0;
    }));
  }
  {  // jobs
    auto a = std::make_shared<FarmArgs>();
    CLI::App* cmd = app.add_subcommand("jobs", "List jobs");
    common(cmd, *a);
    runs.push_back(guard([a, cmd]() -> int { return cmd->parsed() ? list_jobs(*a) : -1; }));
  }
  {  // watch JOB
    auto a = std::make_shared<FarmArgs>();
    auto job = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand("watch", "Show a job's progress until it ends");
    cmd->add_option("job", *job, "job id")->required();
    common(cmd, *a);
    runs.push_back(guard([a, job, cmd]() -> int {
      if (!cmd->parsed()) return -1;
      const v1::JobStatus s = watch(*connect(*a), *job, *a);
      print_status(s, *a);
      return s.state() == v1::JobStatus::DONE ? 0 : 1;
    }));
  }
  {  // fetch JOB -f OUT
    auto a = std::make_shared<FarmArgs>();
    auto job = std::make_shared<std::string>();
    auto outs = std::make_shared<std::vector<std::string>>();
    CLI::App* cmd = app.add_subcommand("fetch", "Download a job's latest image");
    cmd->add_option("job", *job, "job id")->required();
    cmd->add_option("-f", *outs, "output .exr or .png (repeat for both)")->required();
    common(cmd, *a);
    runs.push_back(guard([a, job, outs, cmd]() -> int {
      if (!cmd->parsed()) return -1;
      fetch(*connect(*a), *job, *outs, *a);
      return 0;
    }));
  }
  {  // cancel JOB
    auto a = std::make_shared<FarmArgs>();
    auto job = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand("cancel", "Cancel a job (what was rendered is kept)");
    cmd->add_option("job", *job, "job id")->required();
    common(cmd, *a);
    runs.push_back(guard([a, job, cmd]() -> int {
      if (!cmd->parsed()) return -1;
      v1::JobId req;
      req.set_id(*job);
      v1::JobStatus s;
      check(connect(*a)->CancelJob(ctx().get(), req, &s), *a);
      print_status(s, *a);
      return 0;
    }));
  }
  return runs;
}

}  // namespace tessera
