// libFuzzer target: the glTF 2.0 loader (.gltf text or .glb, by the first bytes), then
// the acceleration structure. Any input may be refused with a SceneError; nothing may
// crash, hang or throw anything else. The loader reads files, so each input is written to
// a private temporary folder first.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/accel/accel.h"
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
  } catch (const tessera::SceneError&) {
  }
  return 0;
}
