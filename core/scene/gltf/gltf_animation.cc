#include "core/scene/gltf/gltf_animation.h"

#include <algorithm>
#include <map>
#include <set>
#include <utility>

#include "core/scene/gltf/gltf_accessors.h"
#include "core/scene/gltf/gltf_skins.h"

namespace tessera {

int32_t GltfAnimationBuilder::add_node(const SceneAnimation::Node& node) {
  animation_.nodes.push_back(node);
  return int32_t(animation_.nodes.size() - 1);
}

void GltfAnimationBuilder::add_mesh(uint32_t scene_mesh, int32_t node_entry, const GltfPrimitive& primitive) {
  const std::vector<float>& p3 = primitive.positions;
  const std::vector<float>& n3 = primitive.normals;
  SceneAnimation::MeshBinding b;
  b.mesh = scene_mesh;
  b.node = uint32_t(node_entry);
  b.positions.resize(p3.size() / 3);
  for (size_t i = 0; i < b.positions.size(); ++i) b.positions[i] = Vec3{p3[3 * i], p3[3 * i + 1], p3[3 * i + 2]};
  b.normals.resize(n3.size() / 3);
  for (size_t i = 0; i < b.normals.size(); ++i) b.normals[i] = Vec3{n3[3 * i], n3[3 * i + 1], n3[3 * i + 2]};
  b.tangents = primitive.tangents;
  b.morph = primitive.morph;
  b.skin = primitive.skin;
  b.indices = primitive.mesh.indices;
  if (primitive.mirrored)  // back to the file's winding: each pose fixes it for its own transform
    for (size_t t = 0; t < b.indices.size(); t += 3) std::swap(b.indices[t + 1], b.indices[t + 2]);
  animation_.meshes.push_back(std::move(b));
}

void GltfAnimationBuilder::add_light(uint32_t scene_light, int32_t node_entry) {
  animation_.lights.push_back({scene_light, uint32_t(node_entry)});
}

void GltfAnimationBuilder::set_camera(int32_t node_entry) { animation_.camera_node = node_entry; }

std::shared_ptr<const SceneAnimation> GltfAnimationBuilder::finish(GltfContext& ctx) {
  const tinygltf::Model& model = ctx.model;
  for (size_t ai = 0; ai < model.animations.size(); ++ai) {
    const tinygltf::Animation& an = model.animations[ai];
    const std::string el = "animations[" + std::to_string(ai) + "]";
    SceneAnimation::Clip clip;
    clip.name = an.name;
    // The specification's rule: each (node, path) animated once in an animation. (A file of
    // 3,000 channels on one node took 52 s a frame: every pose evaluates every channel.)
    std::map<std::pair<int, std::string>, size_t> animated;
    for (size_t ci = 0; ci < an.channels.size(); ++ci) {
      const tinygltf::AnimationChannel& ch = an.channels[ci];
      const std::string cel = el + ".channels[" + std::to_string(ci) + "]";
      if (ch.sampler < 0 || size_t(ch.sampler) >= an.samplers.size())
        ctx.fail(cel, "sampler " + std::to_string(ch.sampler) + " does not exist");
      if (ch.target_node < 0 || size_t(ch.target_node) >= model.nodes.size())
        ctx.fail(cel, "target node " + std::to_string(ch.target_node) + " does not exist");
      if (const auto [at, added] = animated.try_emplace({ch.target_node, ch.target_path}, ci); !added)
        ctx.fail(cel, "nodes[" + std::to_string(ch.target_node) + "]'s " + ch.target_path.substr(0, 32) +
                          " is animated by channels[" + std::to_string(at->second) + "] already");
      SceneAnimation::Channel c;
      c.gltf_node = uint32_t(ch.target_node);
      size_t comps = 3;
      if (ch.target_path == "translation") {
        c.path = SceneAnimation::Path::kTranslation;
      } else if (ch.target_path == "rotation") {
        c.path = SceneAnimation::Path::kRotation;
        comps = 4;
      } else if (ch.target_path == "scale") {
        c.path = SceneAnimation::Path::kScale;
      } else if (ch.target_path == "weights") {
        c.path = SceneAnimation::Path::kWeights;
        const tinygltf::Node& target = model.nodes[size_t(ch.target_node)];
        size_t targets = 0;
        if (target.mesh >= 0 && size_t(target.mesh) < model.meshes.size())
          for (const auto& prim : model.meshes[size_t(target.mesh)].primitives)
            targets = std::max(targets, prim.targets.size());
        if (targets == 0)
          ctx.fail(cel, "animates the morph weights of nodes[" + std::to_string(ch.target_node) +
                            "], whose mesh has no morph targets");
        comps = targets;
      } else {
        ctx.fail(cel, "unknown target path '" + ch.target_path + "' (translation, rotation, scale or weights)");
      }
      if (c.path != SceneAnimation::Path::kWeights && !model.nodes[size_t(ch.target_node)].matrix.empty())
        ctx.fail(cel, "targets nodes[" + std::to_string(ch.target_node) +
                          "], which has a matrix: only nodes given by translation, rotation and scale can be animated");
      const tinygltf::AnimationSampler& smp = an.samplers[size_t(ch.sampler)];
      const std::string sel = el + ".samplers[" + std::to_string(ch.sampler) + "]";
      if (smp.interpolation == "LINEAR" || smp.interpolation.empty())
        c.interpolation = SceneAnimation::Interpolation::kLinear;
      else if (smp.interpolation == "STEP")
        c.interpolation = SceneAnimation::Interpolation::kStep;
      else if (smp.interpolation == "CUBICSPLINE")
        c.interpolation = SceneAnimation::Interpolation::kCubicSpline;
      else
        ctx.fail(sel, "unknown interpolation '" + smp.interpolation + "' (LINEAR, STEP or CUBICSPLINE)");
      const std::vector<float> times = read_accessor_floats(ctx, smp.input, 1, sel + " input");
      if (times.empty()) ctx.fail(sel, "input has no keys");
      for (size_t k = 1; k < times.size(); ++k)
        if (!(times[k] > times[k - 1]))
          ctx.fail(sel, "input times must increase: key " + std::to_string(k) + " (" + std::to_string(times[k]) +
                            " s) does not come after key " + std::to_string(k - 1) + " (" +
                            std::to_string(times[k - 1]) + " s)");
      // Weights are stored as scalars, `comps` of them per key.
      const bool scalar = c.path == SceneAnimation::Path::kWeights;
      const std::vector<float> values = read_accessor_floats(ctx, smp.output, scalar ? 1 : int(comps), sel + " output");
      const bool cubic = c.interpolation == SceneAnimation::Interpolation::kCubicSpline;
      const size_t want = times.size() * (cubic ? 3 : 1);
      if (values.size() / comps != want)
        ctx.fail(sel, "output has " + std::to_string(values.size() / comps) + " elements for " +
                          std::to_string(times.size()) + " input keys; " + (cubic ? "CUBICSPLINE" : smp.interpolation) +
                          " needs " + std::to_string(want));
      c.width = uint32_t(comps);
      c.times.assign(times.begin(), times.end());
      c.values.assign(values.begin(), values.end());
      clip.duration = std::max(clip.duration, c.times.back());
      clip.channels.push_back(std::move(c));
    }
    animation_.clips.push_back(std::move(clip));
  }
  // Keep only what some animation moves.
  std::set<uint32_t> targets;
  for (const auto& clip : animation_.clips)
    for (const auto& c : clip.channels) targets.insert(c.gltf_node);
  std::vector<bool> moves(animation_.nodes.size());
  for (size_t i = 0; i < animation_.nodes.size(); ++i) {
    const auto& e = animation_.nodes[i];
    moves[i] = targets.count(e.gltf_node) || (e.parent >= 0 && moves[size_t(e.parent)]);
  }
  // A skin's joints by their entries in the hierarchy (the first where a node is reached
  // twice); a joint outside it keeps its rest transform.
  std::map<uint32_t, int32_t> entry_of;
  for (size_t i = 0; i < animation_.nodes.size(); ++i) entry_of.emplace(animation_.nodes[i].gltf_node, int32_t(i));
  std::vector<Mat4> rest;
  for (auto& b : animation_.meshes) {
    if (!b.skin) continue;
    if (rest.empty()) rest = gltf_rest_worlds(ctx);
    for (const uint32_t j : b.skin->joints) {
      auto it = entry_of.find(j);
      b.joint_entries.push_back(it == entry_of.end() ? -1 : it->second);
      b.joint_rest.push_back(rest[j]);
    }
  }
  // A mesh moves if its node does, its skin's joints do, or its morph weights are animated
  // (a weights channel targets its node, which then counts as moved).
  auto moving = [&](const SceneAnimation::MeshBinding& b) {
    if (!b.skin) return bool(moves[b.node]);
    bool any = targets.count(animation_.nodes[b.node].gltf_node) > 0;
    for (const int32_t e : b.joint_entries) any |= e >= 0 && moves[size_t(e)];
    return any;
  };
  auto& ms = animation_.meshes;
  ms.erase(std::remove_if(ms.begin(), ms.end(), [&](const auto& b) { return !moving(b); }), ms.end());
  return std::make_shared<const SceneAnimation>(std::move(animation_));
}

}  // namespace tessera
