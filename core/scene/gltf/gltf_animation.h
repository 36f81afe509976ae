// glTF animations, read for posing (docs/gltf.md, Animation; core/scene/animation.h).
// While the node graph is walked, the builder keeps the hierarchy and what moves with each
// node: meshes' object-space geometry, lights, the camera. Then finish() reads every
// animation's channels, checked, and keeps the object-space copies of only the meshes some
// animation moves. A file without animations records nothing and pays nothing.
#pragma once

#include <cstdint>
#include <memory>

#include "core/scene/animation.h"
#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_meshes.h"

namespace tessera {

class GltfAnimationBuilder {
 public:
  // `recording`: the file has animations.
  explicit GltfAnimationBuilder(bool recording) : recording_(recording) {}
  bool recording() const { return recording_; }

  // While recording, in the order the node graph is walked (parents before children).
  // add_node returns the node's entry, which its children and what it carries name.
  int32_t add_node(const SceneAnimation::Node& node);
  void add_mesh(uint32_t scene_mesh, int32_t node_entry, const GltfPrimitive& primitive);
  void add_light(uint32_t scene_light, int32_t node_entry);
  void set_camera(int32_t node_entry);

  // Reads and checks every animation (times increasing, counts agreeing with the
  // interpolation, targets and samplers that exist).
  std::shared_ptr<const SceneAnimation> finish(GltfContext& ctx);

 private:
  bool recording_;
  SceneAnimation animation_;
};

}  // namespace tessera
