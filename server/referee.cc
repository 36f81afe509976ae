#include "server/referee.h"

#include <atomic>
#include <filesystem>

#include "core/render/tile_renderer.h"
#include "core/scene/load.h"

namespace tessera {

namespace fs = std::filesystem;

Referee local_referee(const SceneStore& scenes, std::string scratch_dir) {
  return [&scenes, scratch_dir](const v1::Task& task) {
    const v1::SceneBundle b = scenes.get(task.scene_hash());
    static std::atomic<uint64_t> seq{0};
    const fs::path dir = fs::path(scratch_dir) / (task.scene_hash() + ".referee-" + std::to_string(++seq));
    struct Cleanup {
      fs::path dir;
      ~Cleanup() {
        std::error_code ec;
        fs::remove_all(dir, ec);
      }
    } cleanup{dir};
    const Scene scene = load_scene(unpack_bundle(dir.string(), b.main_file(), b.files()));
    const Rect rect = from_proto(task.tile());
    if (!task.active().empty() && task.active().size() != size_t(rect.area())) throw WireError("active mask size");
    const auto* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
    TileStats stats;
    return TileRenderer(scene, from_proto(task.settings()))
        .render(rect, task.sample_begin(), task.sample_end(), mask, &stats);
  };
}

}  // namespace tessera
