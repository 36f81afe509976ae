#include "client/render_command.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>

#include "core/io/image_io.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

struct RenderArgs {
  std::string scene;
  int spp = 64, light_samples = 1, max_depth = 16, threads = 0, tile = 32, pass_spp = 16;
  std::vector<double> adaptive;
  std::vector<int> resolution{480, 360};
  std::vector<int> window;
  float lens_radius = 0, focal_distance = 4.7f;
  uint64_t seed = 0;
  std::string camera = "cs184";
  std::vector<std::string> outputs;
  std::string stats_json;
  bool quiet = false;
  std::string command_line;
};

std::string format_duration(double s) {
  char buf[32];
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  else
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  return buf;
}

class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet) : quiet_(quiet), tty_(isatty(STDERR_FILENO)) {}
  void operator()(const RenderProgress& p) {
    if (quiet_ || finished_) return;
    finished_ = p.fraction >= 1;
    const double eta = p.fraction > 0 ? p.seconds * (1 - p.fraction) / p.fraction : 0;
    if (tty_) {
      const int width = 30, filled = int(std::lround(p.fraction * width));
      std::fprintf(stderr, "\r[%s%s] %5.1f%%  pass %d/%d  %s elapsed  ETA %s   ", std::string(filled, '#').c_str(),
                   std::string(width - filled, '.').c_str(), 100 * p.fraction, std::min(p.pass + 1, p.passes), p.passes,
                   format_duration(p.seconds).c_str(), format_duration(eta).c_str());
      if (p.fraction >= 1) std::fprintf(stderr, "\n");
    } else if (p.fraction >= 1 || p.seconds - last_ >= 5) {  // plain lines for logs
      last_ = p.seconds;
      std::fprintf(stderr, "progress %.1f%% pass %d/%d elapsed %s eta %s\n", 100 * p.fraction,
                   std::min(p.pass + 1, p.passes), p.passes, format_duration(p.seconds).c_str(),
                   format_duration(eta).c_str());
    }
  }

 private:
  bool quiet_, tty_;
  bool finished_ = false;
  double last_ = -1e9;
};

int run_render(const RenderArgs& a) {
  RenderSettings s;
  s.spp = a.spp;
  s.light_samples = a.light_samples;
  s.max_depth = a.max_depth;
  s.seed = a.seed;
  s.pass_spp = a.pass_spp;
  if (!a.adaptive.empty()) {
    s.adaptive = true;
    s.adaptive_batch = int(a.adaptive[0]);
    s.adaptive_tolerance = float(a.adaptive[1]);
    if (s.adaptive_batch < 1 || !(s.adaptive_tolerance >= 0))
      throw CLI::ValidationError("-a", "batch must be >= 1 and tolerance >= 0");
  }
  s.camera.width = a.resolution[0];
  s.camera.height = a.resolution[1];
  if (s.camera.width < 1 || s.camera.height < 1 || s.camera.width > 65536 || s.camera.height > 65536)
    throw CLI::ValidationError("-r", "width and height must be in 1..65536");
  s.camera.lens_radius = a.lens_radius;
  s.camera.focal_distance = a.focal_distance;
  s.camera.framing = a.camera == "file" ? Framing::kFile : Framing::kCs184;
  if (!a.window.empty()) {
    // CS184 -p x y dx dy: lower-left pixel (x, y) with y counted from the bottom.
    const int x = a.window[0], y = a.window[1], w = a.window[2], h = a.window[3];
    if (x < 0 || y < 0 || w < 1 || h < 1 || x + w > s.camera.width || y + h > s.camera.height)
      throw CLI::ValidationError("-p", "the cell must lie inside the -r image");
    s.window = Rect{x, s.camera.height - (y + h), w, h};
  }

  std::vector<std::string> outputs = a.outputs;
  if (outputs.empty()) {
    std::string stem = a.scene.substr(a.scene.find_last_of('/') + 1);
    stem = stem.substr(0, stem.find_last_of('.'));
    outputs = {stem + ".exr", stem + ".png"};
  }

  const Scene scene = load_scene(a.scene);
  for (const std::string& w : scene.warnings) std::fprintf(stderr, "tessera: warning: %s\n", w.c_str());
  const TileRenderer renderer(scene, s);
  ProgressPrinter printer(a.quiet);
  const RenderResult r = render_image(renderer, a.threads, a.tile, std::ref(printer));

  ImageMetadata meta{{"scene", a.scene},
                     {"seed", std::to_string(a.seed)},
                     {"flags", a.command_line},
                     {"render_seconds", std::to_string(r.seconds)},
                     {"nan_samples", std::to_string(r.stats.nan_samples)}};
  for (const std::string& out : outputs) write_image(out, r.film, meta);

  const uint64_t rays = r.stats.rays.rays + r.stats.rays.shadow_rays;
  const double sps = r.stats.samples / std::max(r.seconds, 1e-9), rps = rays / std::max(r.seconds, 1e-9);
  std::printf("%s: %dx%d, %llu samples in %.2f s: %.2f M samples/s, %.2f M rays/s", a.scene.c_str(), r.film.width(),
              r.film.height(), (unsigned long long)r.stats.samples, r.seconds, sps / 1e6, rps / 1e6);
  if (r.stats.nan_samples) std::printf(", %llu NaN/Inf samples dropped", (unsigned long long)r.stats.nan_samples);
  std::printf(" -> ");
  for (size_t i = 0; i < outputs.size(); ++i) std::printf("%s%s", i ? ", " : "", outputs[i].c_str());
  std::printf("\n");

  if (!a.stats_json.empty()) {
    nlohmann::json j{{"scene", a.scene},
                     {"width", r.film.width()},
                     {"height", r.film.height()},
                     {"spp", a.spp},
                     {"seconds", r.seconds},
                     {"samples", r.stats.samples},
                     {"samples_per_second", sps},
                     {"rays", rays},
                     {"camera_and_bounce_rays", r.stats.rays.rays},
                     {"shadow_rays", r.stats.rays.shadow_rays},
                     {"rays_per_second", rps},
                     {"nan_samples", r.stats.nan_samples},
                     {"mean_luminance", r.film.mean_luminance()},
                     {"self_hits", r.stats.rays.self_hits}};
    std::ofstream f(a.stats_json);
    f << j.dump(2) << "\n";
    if (!f) throw std::runtime_error(a.stats_json + ": cannot write stats");
  }
  return 0;
}

}  // namespace

std::function<int()> add_render_command(CLI::App& app, const std::string& command_line) {
  auto args = std::make_shared<RenderArgs>();
  args->command_line = command_line;
  CLI::App* cmd = app.add_subcommand("render", "Render a scene in this process");
  cmd->add_option("scene", args->scene, "Scene file (.dae)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-s", args->spp, "Camera samples per pixel (a maximum with -a)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 24));
  cmd->add_option("-l", args->light_samples, "Samples per area light per shading point")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 16));
  cmd->add_option("-m", args->max_depth, "Max ray depth: scattering events per path (0 = emitters only)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1 << 16));
  cmd->add_option("-a", args->adaptive, "Adaptive sampling: BATCH TOLERANCE (off unless given)")->expected(2);
  cmd->add_option("-r", args->resolution, "Output width and height; with CS184 framing also the field of view")
      ->expected(2)
      ->capture_default_str();
  cmd->add_option("-t", args->threads, "Threads (0 = all cores)")->capture_default_str()->check(CLI::Range(0, 1024));
  cmd->add_option("-b", args->lens_radius, "Thin-lens radius (0 = pinhole)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e30));
  cmd->add_option("-d", args->focal_distance, "Focal distance along the optical axis")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("-p", args->window, "Render only the cell X Y W H (lower-left pixel, y from the bottom)")
      ->expected(4);
  cmd->add_option("--seed", args->seed, "Random seed")->capture_default_str();
  cmd->add_option("--camera", args->camera, "cs184 (framing of the CS184 renderer) or file (the file's camera)")
      ->capture_default_str()
      ->check(CLI::IsMember({"cs184", "file"}));
  cmd->add_option("-f", args->outputs, "Output image; .exr or .png; repeat for both (default SCENE.exr and SCENE.png)");
  cmd->add_option("--stats-json", args->stats_json, "Write timing figures as JSON");
  cmd->add_option("--tile", args->tile, "Tile size in pixels (does not change the image)")
      ->capture_default_str()
      ->check(CLI::Range(1, 4096));
  cmd->add_option("--pass-spp", args->pass_spp, "Samples per progressive pass")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 24));
  cmd->add_flag("-q,--quiet", args->quiet, "No progress output");
  return [args, cmd] {
    if (!cmd->parsed()) return -1;
    return run_render(*args);
  };
}

}  // namespace tessera
