// libFuzzer target: a SubmitJobRequest as the coordinator receives it (protobuf bytes):
// its settings and scene bundle are checked the way SceneStore::add checks them
// (settings, bundle hash, unpacking with its path checks, loading). Refusals are WireError,
// SettingsError or SceneError; nothing may crash or escape the private folder. Seeds: the
// small scenes, packed (TESSERA_FUZZ_SEEDS=DIR writes them there and exits).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/accel/accel.h"
#include "core/render/settings.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#include "scene_bundle.h"
#include "wire.h"

namespace fs = std::filesystem;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const char* seeds = std::getenv("TESSERA_FUZZ_SEEDS");
  if (!seeds) return 0;
  fs::create_directories(seeds);
  // Small scenes: a seed's size bounds how fast the fuzzer goes.
  for (const char* scene :
       {"/scenes/cornell-spheres.dae", "/tests/fuzz/seeds/gltf/triangle.gltf", "/tests/fuzz/seeds/gltf/triangle.glb"}) {
    const fs::path e = std::string(TESSERA_SOURCE_DIR) + scene;
    tessera::v1::SubmitJobRequest r;
    r.set_version(tessera::kProtocolVersion);
    std::string main;
    tessera::pack_scene(e.string(), &main, r.mutable_files());
    r.set_main_file(main);
    tessera::RenderSettings s;
    s.camera.width = 8;
    s.camera.height = 8;
    *r.mutable_settings() = tessera::to_proto(s);
    std::ofstream(fs::path(seeds) / (e.filename().string() + ".pb"), std::ios::binary) << r.SerializeAsString();
  }
  std::exit(0);
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tessera::v1::SubmitJobRequest req;
  if (!req.ParseFromArray(data, int(size))) return 0;
  static const fs::path root = fs::temp_directory_path() / ("tessera_fuzz_bundle_" + std::to_string(::getpid()));
  const fs::path dir = root / "scene";
  std::error_code ec;
  fs::remove_all(root, ec);
  try {
    (void)tessera::from_proto(req.settings());
    (void)tessera::bundle_hash(req.main_file(), req.files());
    const std::string main = tessera::unpack_bundle(dir.string(), req.main_file(), req.files());
    const tessera::Scene scene = tessera::load_scene(main);
    const tessera::Accel accel(scene);
  } catch (const tessera::WireError&) {
  } catch (const tessera::SettingsError&) {
  } catch (const tessera::SceneError&) {
  }
  // Nothing may be written outside the folder the bundle was unpacked into.
  for (const auto& e : fs::recursive_directory_iterator(root, ec))
    if (fs::relative(e.path(), dir).string().rfind("..", 0) == 0) __builtin_trap();
  fs::remove_all(root, ec);
  return 0;
}
