#include "server/referee.h"

#include "core/render/frame_plan.h"
#include "core/render/tile_renderer.h"
#include "core/scene/load.h"

namespace tessera {
namespace {

RefereeRender render(const SceneStore& scenes, const v1::Task& task) {
  const Scene scene = load_scene(scenes.main_path(task.scene_hash()));
  const Rect rect = from_proto(task.tile());
  if (!task.active().empty() && task.active().size() != size_t(rect.area())) throw WireError("active mask size");
  const auto* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
  TileStats stats;
  const RenderSettings settings = from_proto(task.settings());
  const std::vector<PixelSums> base = task_base(task, rect, settings.sum_planes());
  std::vector<AovSums> aovs;
  std::vector<SplatRecord> splats;
  const TileRenderer renderer(scene, settings);
  std::vector<PixelSums> sums =
      renderer.render_passes(rect, task_passes(task, settings), base.empty() ? nullptr : base.data(), mask, &stats,
                             nullptr, settings.aovs ? &aovs : nullptr, renderer.light_tracing() ? &splats : nullptr);
  return RefereeRender(std::move(sums), std::move(aovs), std::move(splats));
}

}  // namespace

Referee local_referee(const SceneStore& scenes) {
  // The scene is held while the task renders: in turn with the coordinator's other loads.
  return [&scenes](const v1::Task& task) { return scenes.in_turn([&] { return render(scenes, task); }); };
}

}  // namespace tessera
