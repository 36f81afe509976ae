// The render flags shared by `tessera render` and `tessera submit`.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "core/render/settings.h"

namespace tessera {

struct RenderFlags {
  std::string scene;
  int spp = 64, light_samples = 1, max_depth = 16, pass_spp = 16;
  std::vector<double> adaptive;
  std::vector<int> resolution{480, 360};
  std::vector<int> window;
  float lens_radius = 0, focal_distance = 4.7f;
  uint64_t seed = 0;
  std::string camera = "auto";  // cs184 for .dae, the file's own camera for glTF
  std::vector<std::string> outputs;
};

void add_render_flags(CLI::App* cmd, RenderFlags& f);
// Validates and converts; throws CLI::ValidationError naming the flag.
RenderSettings to_settings(const RenderFlags& f);
// -f values, or SCENE.exr and SCENE.png in the current folder.
std::vector<std::string> output_paths(const RenderFlags& f);

}  // namespace tessera
