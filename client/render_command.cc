#include "client/render_command.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>

#include "client/progress.h"
#include "client/render_flags.h"
#include "core/denoise/denoise_exr.h"
#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/io/preview.h"
#include "core/render/frames.h"
#include "core/render/lighting.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

struct RenderArgs {
  RenderFlags flags;
  int threads = 0;
  std::string stats_json;
  bool quiet = false;
  std::string command_line;
};

class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet) : bar_(quiet) {}
  void operator()(const RenderProgress& p) {
    char what[64];
    std::snprintf(what, sizeof what, "passes %u/%u", p.frame_passes, p.passes);
    bar_.update(p.fraction, what, p.seconds);
  }

 private:
  ProgressBar bar_;
};

// Writes every output it can: one that cannot be written (a folder in its place, a full
// disk) does not lose the others, which were dropped after the first failure; the failures
// are thrown together after.
void write_each(const std::vector<std::string>& outputs, const std::function<void(const std::string&)>& write) {
  std::string failed;
  for (const std::string& out : outputs) try {
      write(out);
    } catch (const std::exception& e) {
      failed += (failed.empty() ? "" : "; ") + std::string(e.what());
    }
  if (!failed.empty()) throw std::runtime_error(failed);
}

// --denoise: the noisy EXR is written first (the first .exr asked for, else a temporary
// beside the first output) and denoised in place, as the coordinator does a farm job's:
// one path, so the same bits. The other outputs are made from the denoised file.
double write_denoised(const RenderResult& r, const ImageMetadata& meta, const RenderSettings& s,
                      const std::vector<std::string>& outputs, int threads) {
  const auto first_exr = std::find_if(outputs.begin(), outputs.end(), is_exr_path);
  const std::string exr = first_exr != outputs.end() ? *first_exr : outputs.front() + ".noisy.exr";
  write_image(exr, r.film, meta, &r.aovs, s.aovs, s.image_rect());
  DenoiseOptions options;
  options.threads = threads;
  const DenoiseReport d = denoise_exr(exr, exr, options);
  std::optional<std::string> png;
  std::vector<std::string> rest;
  for (const std::string& out : outputs)
    if (out != exr) rest.push_back(out);
  try {
    write_each(rest, [&](const std::string& out) {
      if (is_exr_path(out)) return copy_file_atomic(exr, out);
      // (the colour alone: not the AOV layers and the noisy copy; written as it is encoded)
      if (png) return copy_file_atomic(*png, out);
      write_full_png(exr, out);
      png = out;
    });
  } catch (const std::exception&) {
    if (first_exr == outputs.end()) std::remove(exr.c_str());
    throw;
  }
  if (first_exr == outputs.end()) std::remove(exr.c_str());
  return d.seconds;
}

int render_frame(const RenderArgs& a, TileRenderer& renderer, RenderSettings s,
                 const std::vector<std::string>& outputs) {
  for (const std::string& p : outputs) make_parent_folder(p);  // (a frame's: out/####/a.exr)
  ProgressPrinter printer(a.quiet);
  const RenderResult r = render_image(renderer, a.threads, std::ref(printer));

  ImageMetadata meta{{"scene", a.flags.scene},
                     {"seed", std::to_string(s.seed)},
                     {"flags", a.command_line},
                     {"render_seconds", std::to_string(r.seconds)},
                     {"nan_samples", std::to_string(r.stats.nan_samples)}};
  if (s.frame) {
    meta["frame"] = std::to_string(*s.frame);
    meta["time"] = fmt::format("{}", s.time());  // seconds: frame / fps, shortest exact
  }
  if (s.exposure != 0) meta[kExposureAttribute] = exposure_text(s.exposure);
  if (s.aovs) meta["aovs"] = aov_names(s.aovs);
  double denoise_seconds = 0;
  if (s.denoise)
    denoise_seconds = write_denoised(r, meta, s, outputs, a.threads);
  else
    write_each(outputs,
               [&](const std::string& out) { write_image(out, r.film, meta, &r.aovs, s.aovs, s.image_rect()); });

  const uint64_t rays = r.stats.rays.rays + r.stats.rays.shadow_rays;
  const double sps = r.stats.samples / std::max(r.seconds, 1e-9), rps = rays / std::max(r.seconds, 1e-9);
  std::printf("%s: %dx%d, %llu samples in %.2f s: %.2f M samples/s, %.2f M rays/s", a.flags.scene.c_str(),
              r.film.width(), r.film.height(), (unsigned long long)r.stats.samples, r.seconds, sps / 1e6, rps / 1e6);
  if (r.stats.nan_samples) std::printf(", %llu NaN/Inf samples dropped", (unsigned long long)r.stats.nan_samples);
  if (s.denoise) std::printf(", denoised in %.2f s", denoise_seconds);
  if (r.light_tracing.on)
    std::printf(", %llu light paths, %llu splats", (unsigned long long)r.light_paths,
                (unsigned long long)r.stats.rays.splats);
  if (r.dropped_splats) std::printf(" (%llu dropped)", (unsigned long long)r.dropped_splats);
  std::printf(" -> ");
  for (size_t i = 0; i < outputs.size(); ++i) std::printf("%s%s", i ? ", " : "", outputs[i].c_str());
  std::printf("\n");

  if (!a.stats_json.empty()) {
    nlohmann::json j{{"scene", a.flags.scene},
                     {"width", r.film.width()},
                     {"height", r.film.height()},
                     {"spp", s.spp},
                     {"seconds", r.seconds},
                     {"denoise_seconds", denoise_seconds},
                     {"samples", r.stats.samples},
                     {"samples_per_second", sps},
                     {"rays", rays},
                     {"camera_and_bounce_rays", r.stats.rays.rays},
                     {"shadow_rays", r.stats.rays.shadow_rays},
                     {"rays_per_second", rps},
                     {"nan_samples", r.stats.nan_samples},
                     {"mean_luminance", r.film.mean_luminance()},
                     {"self_hits", r.stats.rays.self_hits},
                     {"light_tracer", r.light_tracing.on},
                     {"light_tracer_why", r.light_tracing.why},
                     {"light_paths", r.light_paths},
                     {"splats", r.stats.rays.splats},
                     {"split_paths", r.stats.rays.split_paths},
                     {"dropped_splats", r.dropped_splats}};
    const std::string path = s.frame ? frame_path(a.stats_json, *s.frame) : a.stats_json;  // one per frame with ####
    std::ofstream f(path);
    f << j.dump(2) << "\n";
    if (!f) throw std::runtime_error(path + ": cannot write stats");
  }
  return 0;
}

int run_render(const RenderArgs& a) {
  RenderSettings s = to_settings(a.flags);
  std::vector<std::string> outputs = output_paths(a.flags);
  const std::vector<int> frames = sequence_frames(a.flags);
  if (frames.size() > 1 && !a.stats_json.empty() && a.stats_json.find('#') == std::string::npos)  // (each overwrote it)
    throw CLI::ValidationError("--stats-json",
                               "several frames need a #### in its path, one file a frame (got '" + a.stats_json + "')");
  prepare_outputs(outputs);  // before the render: a typo costs nothing
  const Scene scene = load_scene(a.flags.scene);
  print_scene_notes(scene, s, stderr);
  TileRenderer::check_settings(scene, s, frames);  // every frame's camera before the first renders
  TileRenderer renderer(scene, s);
  if (frames.empty()) return render_frame(a, renderer, s, outputs);
  for (const int frame : frames) {  // one scene and one acceleration structure for them all
    s.frame = frame;
    renderer.set_frame(frame);
    std::vector<std::string> paths;
    for (const std::string& out : outputs) paths.push_back(frame_path(out, frame));
    if (const int rc = render_frame(a, renderer, s, paths)) return rc;
  }
  return 0;
}

}  // namespace

std::function<int()> add_render_command(CLI::App& app, const std::string& command_line) {
  auto args = std::make_shared<RenderArgs>();
  args->command_line = command_line;
  CLI::App* cmd = app.add_subcommand("render", "Render a scene in this process");
  add_render_flags(cmd, args->flags);
  cmd->add_option("-t,--threads", args->threads, "Threads (0 = all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--stats-json", args->stats_json, "Write timing figures as JSON");
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  return [args, cmd] {
    if (!cmd->parsed()) return -1;
    return run_render(*args);
  };
}

}  // namespace tessera
