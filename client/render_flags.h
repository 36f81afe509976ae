// The render flags shared by `tessera render` and `tessera submit`. Most bind straight to
// RenderSettings fields (documented there); the few below need converting.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "core/render/settings.h"

namespace tessera {

struct RenderFlags {
  std::string scene;
  RenderSettings settings;
  std::vector<double> adaptive;           // -a BATCH TOLERANCE
  std::vector<int> resolution{480, 360};  // -r W H
  std::vector<int> window;                // -p X Y W H, lower-left pixel, Y from the bottom (CS184)
  std::string camera = "auto";            // cs184 for .dae, the file's own camera for glTF
  bool no_nee = false, no_mis = false;
  std::vector<std::string> outputs;
  std::string frames;       // --frames: a sequence
  std::string camera_path;  // --camera-path FILE
  std::vector<float> env_color;
  std::string env;  // --env FILE  // --env-color R G B
  bool no_default_env = false;
  double turntable = 0;               // --turntable FRAMES: one turn in this many frames
  std::string aovs;                   // --aov LIST
  std::string light_tracer = "auto";  // --light-tracer off|on|auto
};

void add_render_flags(CLI::App* cmd, RenderFlags& f);
// Converts and validates (RenderSettings::validate()); throws CLI::ValidationError naming
// the flag, or SceneError for a scene of unknown format.
RenderSettings to_settings(const RenderFlags& f);
// -f values, or SCENE.exr and SCENE.png in the current folder (SCENE.####.exr and
// SCENE.####.png for a sequence).
std::vector<std::string> output_paths(const RenderFlags& f);
// Checks -f outputs before anything is rendered or downloaded: an unknown extension is a
// usage error (CLI::ValidationError, exit 2), and a missing folder is created (an error
// naming it if it cannot be). A folder whose name holds the frame's #### is made when the
// frame is written.
void prepare_outputs(const std::vector<std::string>& outputs);
// The frames of --frames (empty without it). Throws CLI::ValidationError naming --frames
// for a bad range, --frame given too, or several frames and an -f path without ####.
std::vector<int> sequence_frames(const RenderFlags& f);

}  // namespace tessera
