#include "client/render_flags.h"

#include <charconv>
#include <cmath>
#include <filesystem>

#include "core/io/files.h"
#include "core/render/aov.h"
#include "core/render/frames.h"
#include "core/scene/load.h"

namespace tessera {

void add_render_flags(CLI::App* cmd, RenderFlags& f) {
  RenderSettings& s = f.settings;
  cmd->add_option("scene", f.scene, "Scene file (.dae, .gltf, .glb)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-s", s.spp, "Camera samples per pixel (a maximum with -a or --noise-target)")->capture_default_str();
  cmd->add_option("-l", s.light_samples, "Samples per area light per shading point")->capture_default_str();
  cmd->add_option("-m", s.max_depth, "Max ray depth: scattering events per path (0 = emitters only)")
      ->capture_default_str();
  cmd->add_option("-a", f.adaptive, "Adaptive sampling: BATCH TOLERANCE (off unless given)")->expected(2);
  cmd->add_option("-r", f.resolution, "Output width and height; with CS184 framing also the field of view")
      ->expected(2)
      ->capture_default_str();
  cmd->add_option("-b", s.camera.lens_radius, "Thin-lens radius (0 = pinhole)")->capture_default_str();
  cmd->add_option("-d", s.camera.focal_distance, "Focal distance along the optical axis")->capture_default_str();
  cmd->add_option("-p", f.window, "Render only the cell X Y W H (lower-left pixel, y from the bottom)")->expected(4);
  // (Checked as text: CLI11 saturates, so -1, 2^64 and 1e23 all became 2^64 - 1, one image.)
  cmd->add_option("--seed", s.seed, "Random seed")->capture_default_str()->check([](const std::string& v) {
    uint64_t n = 0;
    const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
    return !v.empty() && ec == std::errc() && end == v.data() + v.size()
               ? std::string()
               : "must be a whole number in 0..18446744073709551615 (got '" + v + "')";
  });
  cmd->add_option("--frame", s.frame, "Frame number of a sequence: its random numbers depend on it (none: a still)");
  cmd->add_option("--frames", f.frames,
                  "A sequence: 1-240, 1-240x2, 1,5,9 (each frame as --frame N alone; -f paths need ####)");
  cmd->add_option("--camera-path", f.camera_path,
                  "Keyframed camera for a sequence (JSON: eye, target, up, fov, lens_radius, focal_distance, "
                  "max_depth by frame; docs/sequences.md)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--turntable", f.turntable,
                  "Orbit the camera about the scene's vertical axis, one turn in this many frames");
  cmd->add_option("--env-color", f.env_color,
                  "A uniform environment around the scene: radiance R G B from every direction")
      ->expected(3);
  cmd->add_option("-e,--env", f.env,
                  "Environment map around the scene: a lat-long .exr or .hdr image (CS184's -e), importance sampled")
      ->check(CLI::ExistingFile);
  cmd->add_option("--env-strength", s.environment_strength, "Scales the environment (image, colour or default)")
      ->capture_default_str();
  cmd->add_option("--env-rotate", s.environment_rotation, "Turns the environment map by DEGREES about +Y")
      ->capture_default_str();
  cmd->add_option("--exposure", s.exposure,
                  "EV of the PNGs and previews (linear x 2^EV; for scenes in physical units); EXRs keep linear values")
      ->capture_default_str();
  cmd->add_flag("--no-default-env", f.no_default_env,
                "No neutral environment for a glTF scene without lights (it renders black)");
  cmd->add_option("--animation", s.animation,
                  "glTF animation that frames follow, by name or index (default: the first)");
  cmd->add_option("--fps", s.fps, "Frames per second: a frame's time is frame / fps (animation)")
      ->capture_default_str();
  cmd->add_option("--camera", f.camera, "cs184 (framing of the CS184 renderer) or file (the file's camera)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "cs184", "file"}));
  cmd->add_option("-f", f.outputs, "Output image; .exr or .png; repeat for both (default SCENE.exr and SCENE.png)");
  cmd->add_option("--pass-spp", s.pass_spp, "Samples per progressive pass")->capture_default_str();
  cmd->add_option("--tile", s.tile_size, "Tile size in pixels (changes the image only with --noise-target)")
      ->capture_default_str();
  cmd->add_option("--noise-target", s.noise_target,
                  "Stop refining a tile once its estimated relative error is below this (0 = off)")
      ->capture_default_str();
  cmd->add_option("--aov", f.aovs,
                  "AOV layers in the EXR beside the image, from the camera samples' first hits: a list of alpha, "
                  "albedo, normal, depth, id (or all), halves (the even and odd samples' means), or denoising "
                  "(albedo, normal, depth, halves: what tessera denoise needs)");
  cmd->add_flag("--denoise", s.denoise,
                "Denoise the final image (the noisy one is kept in the EXR as noisy.R/G/B); adds --aov denoising");
  cmd->add_option("--light-tracer", f.light_tracer,
                  "Light paths for caustics (camera -> diffuse -> mirror/glass -> light): on, off, or auto (on where "
                  "the scene has mirror or glass surfaces and a finite light)")
      ->capture_default_str()
      ->check(CLI::IsMember({"off", "on", "auto"}));
  cmd->add_flag("--no-nee", f.no_nee, "Benchmarking: no next-event estimation (BSDF sampling only)");
  cmd->add_flag("--no-mis", f.no_mis, "Benchmarking: light sampling without MIS");
}

RenderSettings to_settings(const RenderFlags& f) {
  RenderSettings s = f.settings;
  if (!f.adaptive.empty()) {
    s.adaptive = true;
    // Out-of-range doubles become values validate() refuses, not undefined conversions.
    // A batch is whole samples (2.7 was cut to 2).
    s.adaptive_batch =
        f.adaptive[0] >= 1 && f.adaptive[0] <= RenderSettings::kMaxSpp && f.adaptive[0] == std::floor(f.adaptive[0])
            ? int(f.adaptive[0])
            : 0;
    s.adaptive_tolerance = float(f.adaptive[1]);
  }
  s.camera.width = f.resolution[0];
  s.camera.height = f.resolution[1];
  s.camera.framing = f.camera == "file" || (f.camera == "auto" && scene_format(f.scene) != SceneFormat::kCollada)
                         ? Framing::kFile
                         : Framing::kCs184;
  if (!f.window.empty()) {
    // CS184 -p x y dx dy: lower-left pixel (x, y) with y counted from the bottom.
    const int x = f.window[0], y = f.window[1], w = f.window[2], h = f.window[3];
    s.window = Rect{x, s.camera.height - (y + h), w, h};
    if (w < 1 || h < 1 || y < 0) s.window = Rect{-1, -1, 1, 1};  // refused below, by -p
  }
  s.nee = !f.no_nee;
  s.light_tracer = f.light_tracer == "on"     ? RenderSettings::LightTracer::kOn
                   : f.light_tracer == "auto" ? RenderSettings::LightTracer::kAuto
                                              : RenderSettings::LightTracer::kOff;
  s.mis = !f.no_mis;
  try {
    s.aovs = parse_aovs(f.aovs);
    if (s.denoise) s.aovs |= kAovDenoising;
  } catch (const SettingsError& e) {
    throw CLI::ValidationError(e.flag(), std::string(e.what()).substr(e.flag().size() + 2));
  }
  if (!f.env_color.empty()) s.environment = Rgb(f.env_color[0], f.env_color[1], f.env_color[2]);
  s.default_environment = !f.no_default_env;
  if (!f.env.empty()) s.environment_map = std::filesystem::absolute(f.env).string();
  try {
    if (!f.camera_path.empty() || f.turntable != 0) {
      CameraPath path;
      if (!f.camera_path.empty()) {
        try {
          path = CameraPath::parse(read_file_bytes(f.camera_path));
        } catch (const SettingsError& e) {
          throw SettingsError("--camera-path",
                              f.camera_path + ": " + std::string(e.what()).substr(e.flag().size() + 2));
        } catch (const std::runtime_error& e) {
          throw SettingsError("--camera-path", e.what());
        }
      }
      if (f.turntable != 0) {
        if (!std::isfinite(f.turntable)) throw SettingsError("--turntable", "must be a finite number of frames");
        CameraPath::Turntable t;
        t.frames = f.turntable;
        // (Angle 0 at frame 0 whatever --frames says, so that a sequence's frame is the image
        // --frame N --turntable gives alone: it started at --frames' first, and a frame
        // rendered again by itself faced elsewhere.)
        path.turntable = t;
      }
      s.camera.path = std::make_shared<const CameraPath>(std::move(path));
    }
    s.validate();
  } catch (const SettingsError& e) {
    throw CLI::ValidationError(e.flag(), std::string(e.what()).substr(e.flag().size() + 2));
  }
  return s;
}

std::vector<std::string> output_paths(const RenderFlags& f) {
  if (!f.outputs.empty()) return f.outputs;
  std::string stem = f.scene.substr(f.scene.find_last_of('/') + 1);
  stem = stem.substr(0, stem.find_last_of('.'));
  if (!f.frames.empty()) stem += ".####";
  return {stem + ".exr", stem + ".png"};
}

void prepare_outputs(const std::vector<std::string>& outputs) {
  for (const std::string& out : outputs) {
    const std::filesystem::path p(out);
    if (p.extension() != ".exr" && p.extension() != ".png")
      throw CLI::ValidationError("-f", out + ": unknown image format (use .exr or .png)");
    if (p.parent_path().string().find('#') == std::string::npos) make_parent_folder(out);  // (a frame's: when written)
  }
}

std::vector<int> sequence_frames(const RenderFlags& f) {
  if (f.frames.empty()) return {};
  if (f.settings.frame) throw CLI::ValidationError("--frames", "give --frames or --frame, not both");
  std::vector<int> frames;
  try {
    frames = parse_frames(f.frames);
  } catch (const SettingsError& e) {
    throw CLI::ValidationError(e.flag(), std::string(e.what()).substr(e.flag().size() + 2));
  }
  if (frames.size() > 1)
    for (const std::string& out : output_paths(f))
      if (out.find('#') == std::string::npos)
        throw CLI::ValidationError("--frames", "several frames need a #### in every -f path (got '" + out + "')");
  return frames;
}

}  // namespace tessera
