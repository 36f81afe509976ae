// libFuzzer target: the glTF 2.0 loader (.gltf text or .glb, by the first bytes), then
// the acceleration structure, and for animated files a few poses of each animation (with
// the static part instanced, as frames are rendered). Any input may be refused with a SceneError; nothing may
// crash, hang or throw anything else. The loader reads files, so each input is written to
// a private temporary folder first.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "core/accel/accel.h"
#include "core/scene/animation.h"
#include "core/scene/gltf/gltf_loader.h"
#include "core/scene/scene_error.h"

namespace {
const std::filesystem::path& dir() {
  static const std::filesystem::path d = [] {
    auto p = std::filesystem::temp_directory_path() / ("tessera_fuzz_gltf_" + std::to_string(::getpid()));
    std::filesystem::create_directories(p);
    return p;
  }();
  return d;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  const std::string path = (dir() / (glb ? "scene.glb" : "scene.gltf")).string();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  }
  try {
    const tessera::Scene scene = tessera::load_gltf_file(path);
    const tessera::Accel accel(scene);
    if (scene.animation) {
      std::vector<bool> moving(scene.meshes.size(), false);
      for (const auto& b : scene.animation->meshes) moving.at(b.mesh) = true;
      auto fixed = std::make_shared<const tessera::Accel>(scene, moving);
      for (size_t c = 0; c < scene.animation->clips.size() && c < 4; ++c) {
        const double d = scene.animation->clips[c].duration;
        for (const double t : {-1.0, 0.0, d / 3, d, d + 1}) {
          const tessera::Scene pose = tessera::pose_scene(scene, c, t);
          const tessera::Accel frame(pose, fixed, moving);
        }
      }
    }
  } catch (const tessera::SceneError&) {
  }
  return 0;
}
