// libFuzzer target: the CS184 COLLADA loader, then the acceleration structure a worker
// builds from what it loaded. Any input may be refused with a SceneError; nothing may
// crash, hang or throw anything else. tests/fuzz/README.md says how to run it.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/accel/accel.h"
#include "core/scene/collada/collada_loader.h"
#include "core/scene/scene_error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const tessera::Scene scene =
        tessera::load_collada_string(std::string(reinterpret_cast<const char*>(data), size), "fuzz.dae");
    const tessera::Accel accel(scene);  // what Embree is given must be traceable
  } catch (const tessera::SceneError&) {
  }
  return 0;
}
