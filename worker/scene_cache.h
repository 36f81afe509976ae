// A worker's scenes and renderers: each scene fetched once per content hash and kept on
// disk (a restarted worker does not fetch it again), loaded once, and a renderer built per
// (scene, settings), a few of them kept. Renderers of frames of one sequence share one
// acceleration structure.
#pragma once

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "core/render/tile_renderer.h"
#include "core/scene/scene.h"
#include "tessera.grpc.pb.h"

namespace tessera::worker {

// A scene and a renderer for one (scene, settings).
struct PreparedRenderer {
  std::shared_ptr<Scene> scene;  // outlives the renderer, which refers to it
  std::unique_ptr<TileRenderer> renderer;
  std::string base_key;  // scene and settings but the frame: renderers sharing one BVH
};

class SceneCache {
 public:
  // Asks the coordinator for a scene's bundle; throws what the call failed with.
  using FetchBundle = std::function<v1::SceneBundle(const std::string& hash)>;
  static constexpr size_t kKeptRenderers = 8;  // jobs alternate by priority, frames follow each other

  SceneCache(std::string dir, FetchBundle fetch) : dir_(std::move(dir)), fetch_(std::move(fetch)) {}

  // The renderer for a task's scene and settings. Throws WireError (a bad hash, a bundle
  // that does not match it), SceneError and SettingsError (a scene or settings this
  // worker cannot render), or what fetching throws.
  std::shared_ptr<const PreparedRenderer> prepare(const v1::Task& task);

 private:
  std::shared_ptr<Scene> scene(const std::string& hash);  // loaded once per content hash

  std::string dir_;
  FetchBundle fetch_;
  std::map<std::string, std::shared_ptr<Scene>> scenes_;  // by content hash
  std::map<std::string, std::shared_ptr<const PreparedRenderer>> prepared_;
  std::deque<std::string> prepared_order_;
};

}  // namespace tessera::worker
