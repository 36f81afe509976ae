#include "client/render_flags.h"

#include <filesystem>

namespace tessera {

void add_render_flags(CLI::App* cmd, RenderFlags& f) {
  cmd->add_option("scene", f.scene, "Scene file (.dae)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-s", f.spp, "Camera samples per pixel (a maximum with -a)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 24));
  cmd->add_option("-l", f.light_samples, "Samples per area light per shading point")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 16));
  cmd->add_option("-m", f.max_depth, "Max ray depth: scattering events per path (0 = emitters only)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1 << 16));
  cmd->add_option("-a", f.adaptive, "Adaptive sampling: BATCH TOLERANCE (off unless given)")->expected(2);
  cmd->add_option("-r", f.resolution, "Output width and height; with CS184 framing also the field of view")
      ->expected(2)
      ->capture_default_str();
  cmd->add_option("-b", f.lens_radius, "Thin-lens radius (0 = pinhole)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e30));
  cmd->add_option("-d", f.focal_distance, "Focal distance along the optical axis")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("-p", f.window, "Render only the cell X Y W H (lower-left pixel, y from the bottom)")->expected(4);
  cmd->add_option("--seed", f.seed, "Random seed")->capture_default_str();
  cmd->add_option("--camera", f.camera, "cs184 (framing of the CS184 renderer) or file (the file's camera)")
      ->capture_default_str()
      ->check(CLI::IsMember({"cs184", "file"}));
  cmd->add_option("-f", f.outputs, "Output image; .exr or .png; repeat for both (default SCENE.exr and SCENE.png)");
  cmd->add_option("--pass-spp", f.pass_spp, "Samples per progressive pass")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 24));
}

RenderSettings to_settings(const RenderFlags& a) {
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
  const auto ext = std::filesystem::path(a.scene).extension().string();
  const bool dae = ext == ".dae" || ext == ".DAE";
  s.camera.framing = a.camera == "file" || (a.camera == "auto" && !dae) ? Framing::kFile : Framing::kCs184;
  if (!a.window.empty()) {
    // CS184 -p x y dx dy: lower-left pixel (x, y) with y counted from the bottom.
    const int x = a.window[0], y = a.window[1], w = a.window[2], h = a.window[3];
    if (x < 0 || y < 0 || w < 1 || h < 1 || x + w > s.camera.width || y + h > s.camera.height)
      throw CLI::ValidationError("-p", "the cell must lie inside the -r image");
    s.window = Rect{x, s.camera.height - (y + h), w, h};
  }
  return s;
}

std::vector<std::string> output_paths(const RenderFlags& f) {
  if (!f.outputs.empty()) return f.outputs;
  std::string stem = f.scene.substr(f.scene.find_last_of('/') + 1);
  stem = stem.substr(0, stem.find_last_of('.'));
  return {stem + ".exr", stem + ".png"};
}

}  // namespace tessera
