#include "core/scene/gltf/gltf_nodes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "core/scene/gltf/gltf_lights_cameras.h"
#include "core/scene/gltf/gltf_meshes.h"

namespace tessera {
namespace {

constexpr size_t kMaxNodeDepth = 256;

// A node's translation, rotation and scale (glTF's defaults where absent), checked.
struct Trs {
  std::array<double, 3> t{0, 0, 0}, s{1, 1, 1};
  std::array<double, 4> r{0, 0, 0, 1};
};
Trs trs_of(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el) {
  Trs x;
  if (!n.translation.empty()) {
    if (n.translation.size() != 3) ctx.fail(el, "translation needs 3 numbers");
    x.t = {n.translation[0], n.translation[1], n.translation[2]};
  }
  if (!n.rotation.empty()) {
    if (n.rotation.size() != 4) ctx.fail(el, "rotation needs 4 numbers");
    x.r = {n.rotation[0], n.rotation[1], n.rotation[2], n.rotation[3]};
    const double len = std::sqrt(x.r[0] * x.r[0] + x.r[1] * x.r[1] + x.r[2] * x.r[2] + x.r[3] * x.r[3]);
    if (!(len > 0)) ctx.fail(el, "rotation quaternion is zero");
  }
  if (!n.scale.empty()) {
    if (n.scale.size() != 3) ctx.fail(el, "scale needs 3 numbers");
    x.s = {n.scale[0], n.scale[1], n.scale[2]};
  }
  return x;
}

Mat4 local_matrix(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el) {
  if (!n.matrix.empty()) {
    if (n.matrix.size() != 16) ctx.fail(el, "matrix needs 16 numbers");
    std::array<double, 16> m{};
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = n.matrix[size_t(c * 4 + r)];  // glTF is column-major
    return Mat4::from_row_major(m);
  }
  const Trs x = trs_of(ctx, n, el);
  return trs_matrix(x.t, x.r, x.s);
}

// The nodes the walk starts from.
std::vector<int> scene_roots(const GltfContext& ctx) {
  const tinygltf::Model& model = ctx.model;
  if (!model.scenes.empty()) {
    const int s = model.defaultScene >= 0 ? model.defaultScene : 0;
    if (s >= int(model.scenes.size())) ctx.fail("scene", "defaultScene " + std::to_string(s) + " does not exist");
    return model.scenes[size_t(s)].nodes;
  }
  std::vector<int> roots;  // no scenes: every node that is nobody's child
  std::vector<bool> child(model.nodes.size());
  for (const auto& n : model.nodes)
    for (int c : n.children)
      if (c >= 0 && size_t(c) < child.size()) child[size_t(c)] = true;
  for (size_t i = 0; i < child.size(); ++i)
    if (!child[i]) roots.push_back(int(i));
  return roots;
}

class NodeWalk {
 public:
  NodeWalk(GltfContext& ctx, GltfMaterials& materials, GltfAnimationBuilder& animation)
      : ctx_(ctx), materials_(materials), animation_(animation) {}

  // `parent_entry`: the parent's entry in the animation's hierarchy (-1: none).
  void visit(int index, const Mat4& parent, int32_t parent_entry) {
    const std::string el = "nodes[" + std::to_string(index) + "]";
    if (index < 0 || size_t(index) >= ctx_.model.nodes.size()) ctx_.fail(el, "does not exist");
    if (std::find(path_.begin(), path_.end(), index) != path_.end())
      ctx_.fail(el, "the node graph has a cycle through this node");
    if (path_.size() >= kMaxNodeDepth) ctx_.fail(el, "node hierarchy deeper than 256 levels");
    const tinygltf::Node& n = ctx_.model.nodes[size_t(index)];
    const Mat4 local = local_matrix(ctx_, n, el);
    const Mat4 world = parent * local;
    int32_t entry = -1;
    if (animation_.recording()) {  // the hierarchy, for posing frames of an animation
      SceneAnimation::Node e;
      e.gltf_node = uint32_t(index);
      e.parent = parent_entry;
      e.trs = n.matrix.empty();
      e.matrix = local;
      if (e.trs) {
        const Trs x = trs_of(ctx_, n, el);
        e.translation = x.t;
        e.rotation = x.r;
        e.scale = x.s;
      }
      entry = animation_.add_node(e);
    }
    path_.push_back(index);
    if (n.mesh >= 0)
      for (GltfPrimitive& p : read_gltf_mesh(ctx_, materials_, n.mesh, world, el, animation_.recording())) {
        if (animation_.recording()) animation_.add_mesh(uint32_t(ctx_.scene.meshes.size()), entry, p);
        ctx_.scene.meshes.push_back(std::move(p.mesh));
      }
    if (n.camera >= 0) {
      const bool first = !ctx_.scene.camera.present;
      add_gltf_camera(ctx_, n.camera, world, el);
      if (animation_.recording() && first) animation_.set_camera(entry);
    }
    if (const std::optional<int> light = gltf_node_light(ctx_, n, el)) {
      add_gltf_light(ctx_, *light, world, el);
      if (animation_.recording()) animation_.add_light(uint32_t(ctx_.scene.lights.size() - 1), entry);
    }
    for (int c : n.children) visit(c, world, entry);
    path_.pop_back();
  }

 private:
  GltfContext& ctx_;
  GltfMaterials& materials_;
  GltfAnimationBuilder& animation_;
  std::vector<int> path_;  // the nodes from the root to the one visited: a cycle returns to one of them
};

}  // namespace

void add_gltf_nodes(GltfContext& ctx, GltfMaterials& materials, GltfAnimationBuilder& animation) {
  NodeWalk walk(ctx, materials, animation);
  for (int r : scene_roots(ctx)) walk.visit(r, Mat4(), -1);
}

}  // namespace tessera
