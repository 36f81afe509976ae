#include "core/scene/gltf/gltf_nodes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "core/scene/animation.h"
#include "core/scene/gltf/gltf_accessors.h"
#include "core/scene/gltf/gltf_budget.h"
#include "core/scene/gltf/gltf_lights_cameras.h"
#include "core/scene/gltf/gltf_meshes.h"
#include "core/scene/gltf/gltf_skins.h"
#include "core/util/cancel.h"

namespace tessera {
namespace {

constexpr size_t kMaxInstancedTriangles = 50'000'000;
constexpr size_t kMaxInstances = 1 << 20;

// A node's EXT_mesh_gpu_instancing transforms (TRANSLATION, ROTATION, SCALE accessors of
// one count), each applied before the node's world transform; one identity without it.
std::vector<Mat4> gltf_instances(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el) {
  auto ext = n.extensions.find("EXT_mesh_gpu_instancing");
  if (ext == n.extensions.end()) return {Mat4()};
  const std::string xel = el + " EXT_mesh_gpu_instancing";
  if (!ext->second.IsObject() || !ext->second.Has("attributes") || !ext->second.Get("attributes").IsObject())
    ctx.fail(xel, "has no instances (no TRANSLATION, ROTATION or SCALE attributes)");
  const tinygltf::Value& attrs = ext->second.Get("attributes");
  std::vector<float> t, r, s;
  size_t count = 0;
  auto read = [&](const char* name, int comps, std::vector<float>& out) {
    if (!attrs.Has(name)) return;
    if (!attrs.Get(name).IsInt()) ctx.fail(xel, std::string(name) + " is not an accessor index");
    out = read_accessor_floats(ctx, attrs.Get(name).GetNumberAsInt(), comps, xel + " " + name);
    const size_t c = out.size() / size_t(comps);
    if (count && c != count)
      ctx.fail(xel,
               std::string(name) + " has " + std::to_string(c) + " instances, the others " + std::to_string(count));
    count = c;
  };
  read("TRANSLATION", 3, t);
  read("ROTATION", 4, r);
  read("SCALE", 3, s);
  if (count == 0) ctx.fail(xel, "has no instances (no TRANSLATION, ROTATION or SCALE attributes)");
  if (count > kMaxInstances) ctx.fail(xel, std::to_string(count) + " instances is over the 1 M limit");
  std::vector<Mat4> out(count);
  for (size_t i = 0; i < count; ++i) {
    std::array<double, 3> ti{0, 0, 0}, si{1, 1, 1};
    std::array<double, 4> ri{0, 0, 0, 1};
    if (!t.empty()) ti = {t[3 * i], t[3 * i + 1], t[3 * i + 2]};
    if (!r.empty()) ri = {r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]};
    if (!s.empty()) si = {s[3 * i], s[3 * i + 1], s[3 * i + 2]};
    out[i] = trs_matrix(ti, ri, si);
  }
  return out;
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
  // `parent_orientation`: the parent's world transform without its scales (place_light).
  void visit(int index, const Mat4& parent, const Mat4& parent_orientation, int32_t parent_entry) {
    throw_if_cancelled();
    const std::string el = "nodes[" + std::to_string(index) + "]";
    // check_gltf_budget went over this graph first: every node exists, no cycle, no deeper
    // than kMaxGltfNodeDepth.
    const tinygltf::Node& n = ctx_.model.nodes[size_t(index)];
    const bool trs = n.matrix.empty();
    const GltfTrs x = trs ? gltf_trs(ctx_, n, el) : GltfTrs{};  // (read once: the matrix, the pose, the orientation)
    const Mat4 local = trs ? trs_matrix(x.t, x.r, x.s) : gltf_local_matrix(ctx_, n, el);
    const Mat4 world = parent * local;
    const Mat4 orientation = parent_orientation * orientation_of(trs, x.r, local);
    int32_t entry = -1;
    if (animation_.recording()) {  // the hierarchy, for posing frames of an animation
      SceneAnimation::Node e;
      e.gltf_node = uint32_t(index);
      e.parent = parent_entry;
      e.trs = trs;
      e.matrix = local;
      if (e.trs) {
        e.translation = x.t;
        e.rotation = x.r;
        e.scale = x.s;
      }
      entry = animation_.add_node(e);
    }
    const std::vector<Mat4> instances = n.mesh >= 0 ? gltf_instances(ctx_, n, el) : std::vector<Mat4>();
    // Real instances (Scene::instances: each primitive stored once, in object space), but
    // where a pose moves them (animated files, skins): copies, posed as any mesh.
    if (instances.size() > 1 && !animation_.recording() && n.skin < 0) {
      // An instance whose transform has no inverse (scaled to zero along an axis: a flat
      // mesh in that plane keeps its surface) or none in float cannot be placed by Embree's
      // instancing: it is a copy in world space, as a plain node with that scale is.
      std::vector<Mat4> copies;
      std::vector<std::optional<Instance>> placed(instances.size());
      for (size_t k = 0; k < instances.size(); ++k) {
        const Mat4 m = world * instances[k];
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 4; ++c)
            if (!std::isfinite(float(m(r, c))))  // (as Embree gets it)
              ctx_.fail(el, "EXT_mesh_gpu_instancing instance " + std::to_string(k) + "'s transform is not finite");
        placed[k] = Instance::make(0, m);
        if (!placed[k]) copies.push_back(instances[k]);
      }
      for (GltfPrimitive& p : read_gltf_mesh(ctx_, materials_, n, Mat4(), el, false)) {
        const uint32_t id = uint32_t(ctx_.scene.meshes.size());
        p.mesh.instanced = true;
        for (const std::optional<Instance>& in : placed)
          if (in) {
            ctx_.scene.instances.push_back(*in);
            ctx_.scene.instances.back().mesh = id;
          }
        ctx_.scene.meshes.push_back(std::move(p.mesh));
      }
      // The budget counted the mesh once (real instances); each copy is charged before it is read.
      for (const Mat4& inst : copies) {
        ctx_.charge(el, "meshes", uint64_t(std::min(gltf_mesh_bytes(ctx_, n.mesh, false, false), 1e18)));
        for (GltfPrimitive& p : read_gltf_mesh(ctx_, materials_, n, world * inst, el, false)) {
          instanced_triangles_ += p.mesh.triangle_count();
          if (instanced_triangles_ > kMaxInstancedTriangles)
            ctx_.fail(el, "EXT_mesh_gpu_instancing: " + std::to_string(copies.size()) +
                              " instances without an inverse transform (copied) make more than the 50 M triangle "
                              "limit");
          ctx_.scene.meshes.push_back(std::move(p.mesh));
        }
      }
    } else {
      add_copies(n, instances, world, entry, el);
    }
    if (n.camera >= 0) {
      const bool first = !ctx_.scene.camera.present;
      add_gltf_camera(ctx_, n.camera, world, el);
      if (animation_.recording() && first) animation_.set_camera(entry);
    }
    if (const std::optional<int> light = gltf_node_light(ctx_, n, el)) {
      add_gltf_light(ctx_, *light, world, orientation, el);
      if (animation_.recording()) animation_.add_light(uint32_t(ctx_.scene.lights.size() - 1), entry);
    }
    for (int c : n.children) visit(c, world, orientation, entry);
  }

  // Each instance a copy of the mesh in world space (one copy without the extension).
  void add_copies(const tinygltf::Node& n, const std::vector<Mat4>& instances, const Mat4& world, int32_t entry,
                  const std::string& el) {
    for (const Mat4& inst : instances)
      for (GltfPrimitive& p : read_gltf_mesh(ctx_, materials_, n, world * inst, el, animation_.recording())) {
        const uint32_t id = uint32_t(ctx_.scene.meshes.size());
        if (instances.size() > 1) {
          instanced_triangles_ += p.mesh.triangle_count();
          if (instanced_triangles_ > kMaxInstancedTriangles)
            ctx_.fail(el, "EXT_mesh_gpu_instancing: " + std::to_string(instances.size()) +
                              " instances make more than the 50 M triangle limit (an animated or skinned "
                              "node's instances are copies)");
        }
        bool identity = true;
        for (int r = 0; r < 4; ++r)
          for (int c = 0; c < 4; ++c) identity = identity && inst(r, c) == (r == c ? 1.0 : 0.0);
        if (!identity) {  // the extension's instance (one, or each of several)
          // An animated node moves its instances as one: their object space includes the
          // instance's own transform (a single instance's too: it was left out, and every
          // posed frame lost it), and so do its morph targets' displacements.
          for (size_t i = 0; i + 2 < p.positions.size(); i += 3) {
            const Dvec3 q = inst.point(p.positions[i], p.positions[i + 1], p.positions[i + 2]);
            p.positions[i] = float(q.x), p.positions[i + 1] = float(q.y), p.positions[i + 2] = float(q.z);
          }
          const Mat4 nt = inst.normal_matrix();
          for (size_t i = 0; i + 2 < p.normals.size(); i += 3) {
            const Dvec3 q = nt.vector(p.normals[i], p.normals[i + 1], p.normals[i + 2]);
            p.normals[i] = float(q.x), p.normals[i + 1] = float(q.y), p.normals[i + 2] = float(q.z);
          }
          if (p.morph) {
            auto morph = std::make_shared<MorphTargets>(*p.morph);
            for (std::vector<Vec3>& target : morph->positions)
              for (Vec3& d : target) d = inst.vector(d.x, d.y, d.z).to_float();
            for (std::vector<Vec3>& target : morph->normals)
              for (Vec3& d : target) d = nt.vector(d.x, d.y, d.z).to_float();
            p.morph = std::move(morph);
          }
        }
        if (animation_.recording()) animation_.add_mesh(id, entry, p);
        if (p.skin) skinned_.push_back({id, p.skin, p.morph, std::move(p.positions), std::move(p.normals)});
        ctx_.scene.meshes.push_back(std::move(p.mesh));
      }
  }

 private:
  GltfContext& ctx_;
  GltfMaterials& materials_;
  GltfAnimationBuilder& animation_;
  size_t instanced_triangles_ = 0;

 public:
  // Skinned primitives, placed once the walk is over (their joints can come anywhere).
  struct Skinned {
    uint32_t mesh;
    std::shared_ptr<const Skin> skin;
    std::shared_ptr<const MorphTargets> morph;
    std::vector<float> positions, normals;  // object space
  };
  std::vector<Skinned> skinned_;
};

}  // namespace

void add_gltf_nodes(GltfContext& ctx, GltfMaterials& materials, GltfAnimationBuilder& animation) {
  const std::vector<int> roots = scene_roots(ctx);
  check_gltf_budget(ctx, roots);  // before anything is expanded
  NodeWalk walk(ctx, materials, animation);
  for (int r : roots) walk.visit(r, Mat4(), Mat4(), -1);
  if (walk.skinned_.empty()) return;
  const std::vector<Mat4> rest = gltf_rest_worlds(ctx);
  for (const NodeWalk::Skinned& k : walk.skinned_) {
    Mesh& mesh = ctx.scene.meshes[k.mesh];
    place_skinned_mesh(ctx, mesh, *k.skin, k.morph.get(), k.positions, k.normals, rest, "mesh '" + mesh.name + "'");
  }
}

}  // namespace tessera
