#include "worker/scene_cache.h"

#include <filesystem>
#include <fstream>

#include "core/scene/load.h"
#include "scene_bundle.h"
#include "wire.h"

namespace tessera::worker {

namespace fs = std::filesystem;

std::shared_ptr<Scene> SceneCache::scene(const std::string& hash) {
  if (auto it = scenes_.find(hash); it != scenes_.end()) return it->second;
  if (hash.size() != 32 || hash.find_first_not_of("0123456789abcdef") != std::string::npos)
    throw WireError("bad scene hash '" + hash + "'");
  const fs::path dir = fs::path(dir_) / hash;
  const fs::path marker = dir / ".main";
  std::string main;
  if (std::ifstream in(marker); in) {
    std::getline(in, main);  // cached on disk by an earlier run
    main = (dir / main).string();
  } else {
    const v1::SceneBundle bundle = fetch_(hash);
    if (bundle_hash(bundle.main_file(), bundle.files()) != hash)
      throw WireError("scene bundle does not match its hash");
    main = unpack_bundle(dir.string(), bundle.main_file(), bundle.files());
    std::ofstream(marker) << bundle.main_file() << "\n";
  }
  return scenes_[hash] = std::make_shared<Scene>(load_scene(main));
}

std::shared_ptr<const PreparedRenderer> SceneCache::prepare(const v1::Task& task) {
  const std::string key = task.scene_hash() + task.settings().SerializeAsString();
  if (auto it = prepared_.find(key); it != prepared_.end()) return it->second;
  auto p = std::make_shared<PreparedRenderer>();
  const RenderSettings settings = from_proto(task.settings());
  // The frames of a sequence share one acceleration structure: a renderer built for any
  // frame of the same (scene, settings) lends its own to the next frame's.
  v1::RenderSettings base = task.settings();
  base.clear_frame();
  const std::string base_key = task.scene_hash() + base.SerializeAsString();
  std::shared_ptr<const PreparedRenderer> sibling;
  for (const auto& [k, q] : prepared_)
    if (q->base_key == base_key) sibling = q;
  if (sibling) {
    p->scene = sibling->scene;
    p->renderer = std::make_unique<TileRenderer>(*sibling->renderer, settings);
  } else {
    p->scene = scene(task.scene_hash());
    p->renderer = std::make_unique<TileRenderer>(*p->scene, settings);
  }
  p->base_key = base_key;
  // Tasks in flight hold their renderers; the cache keeps the latest few.
  prepared_[key] = p;
  prepared_order_.push_back(key);
  if (prepared_order_.size() > kKeptRenderers) {
    prepared_.erase(prepared_order_.front());
    prepared_order_.pop_front();
  }
  return p;
}

}  // namespace tessera::worker
