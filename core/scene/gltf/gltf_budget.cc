#include "core/scene/gltf/gltf_budget.h"

#include <algorithm>
#include <cstdio>
#include <string>

namespace tessera {
namespace {

std::string count_text(double n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, n < 1e15 ? "%.0f" : "%.3g", n);
  return buf;
}

// Accessor `a`'s declared count; 0 where there is no such accessor.
double accessor_count(const GltfContext& ctx, int a) {
  return a >= 0 && size_t(a) < ctx.model.accessors.size() ? double(ctx.model.accessors[size_t(a)].count) : 0;
}

// A primitive's triangles from its declared counts; 0 for points and lines (not read).
double primitive_triangles(const GltfContext& ctx, const tinygltf::Primitive& p) {
  auto pos = p.attributes.find("POSITION");
  const double n = p.indices >= 0              ? accessor_count(ctx, p.indices)
                   : pos != p.attributes.end() ? accessor_count(ctx, pos->second)
                                               : 0;
  if (p.mode == TINYGLTF_MODE_TRIANGLES || p.mode == -1) return std::floor(n / 3);
  if (p.mode == TINYGLTF_MODE_TRIANGLE_STRIP || p.mode == TINYGLTF_MODE_TRIANGLE_FAN) return std::max(0.0, n - 2);
  return 0;
}

class Budget {
 public:
  explicit Budget(GltfContext& ctx) : ctx_(ctx), memo_(ctx.model.nodes.size()) {}

  struct Count {
    double visits = 0, triangles = 0, meshes = 0;
    double bytes = 0;   // the expanded meshes' arrays (Mesh: positions, normals, indices, ...)
    size_t height = 0;  // the longest chain of nodes from this one down, itself included
  };

  Count node(int index, size_t depth) {
    const std::string el = "nodes[" + std::to_string(index) + "]";
    if (index < 0 || size_t(index) >= memo_.size()) ctx_.fail(el, "does not exist");
    Entry& e = memo_[size_t(index)];
    if (e.state == State::kOpen) ctx_.fail(el, "the node graph has a cycle through this node");
    if (e.state == State::kNew) {
      if (depth >= kMaxGltfNodeDepth) ctx_.fail(el, "node hierarchy deeper than 256 levels");
      e.state = State::kOpen;
      const tinygltf::Node& n = ctx_.model.nodes[size_t(index)];
      Count c;
      c.visits = 1;
      // EXT_mesh_gpu_instancing's instances are copies only where a pose moves them (a file
      // with animations, a skinned node: gltf_nodes); else the mesh is stored once.
      const bool copied = !ctx_.model.animations.empty() || n.skin >= 0;
      if (n.mesh >= 0) {
        const double copies = copied ? instances(n) : 1;
        c.triangles = mesh_triangles(n.mesh) * copies;
        c.meshes = mesh_primitives(n.mesh) * copies;
        c.bytes = gltf_mesh_bytes(ctx_, n.mesh, !ctx_.model.animations.empty(), n.skin >= 0) * copies;
      }
      for (int child : n.children) {
        const Count k = node(child, depth + 1);
        c.visits += k.visits;
        c.triangles += k.triangles;
        c.meshes += k.meshes;
        c.bytes += k.bytes;
        c.height = std::max(c.height, k.height);
      }
      ++c.height;
      e = {State::kDone, c};  // (memo_ never reallocates)
    }
    const Count& c = e.count;
    if (depth + c.height > kMaxGltfNodeDepth) ctx_.fail(el, "node hierarchy deeper than 256 levels");
    return c;
  }

 private:
  enum class State { kNew, kOpen, kDone };
  struct Entry {
    State state = State::kNew;
    Count count;
  };

  // Triangles of a mesh from its primitives' declared counts (the walk checks them later).
  double mesh_triangles(int mesh) const {
    if (size_t(mesh) >= ctx_.model.meshes.size()) return 0;
    double t = 0;
    for (const tinygltf::Primitive& p : ctx_.model.meshes[size_t(mesh)].primitives) t += primitive_triangles(ctx_, p);
    return t;
  }
  double mesh_primitives(int mesh) const {
    return size_t(mesh) < ctx_.model.meshes.size() ? double(ctx_.model.meshes[size_t(mesh)].primitives.size()) : 0;
  }
  // EXT_mesh_gpu_instancing's instance count (its first attribute's), else 1.
  double instances(const tinygltf::Node& n) const {
    auto ext = n.extensions.find("EXT_mesh_gpu_instancing");
    if (ext == n.extensions.end() || !ext->second.IsObject() || !ext->second.Has("attributes")) return 1;
    const tinygltf::Value& attrs = ext->second.Get("attributes");
    for (const char* name : {"TRANSLATION", "ROTATION", "SCALE"})
      if (attrs.IsObject() && attrs.Has(name) && attrs.Get(name).IsInt())
        return std::max(1.0, accessor_count(ctx_, attrs.Get(name).GetNumberAsInt()));
    return 1;
  }

  GltfContext& ctx_;
  std::vector<Entry> memo_;
};

}  // namespace

double gltf_mesh_bytes(const GltfContext& ctx, int mesh, bool posed, bool skinned) {
  if (mesh < 0 || size_t(mesh) >= ctx.model.meshes.size()) return 0;
  double bytes = 0;
  for (const tinygltf::Primitive& p : ctx.model.meshes[size_t(mesh)].primitives) {
    auto pos = p.attributes.find("POSITION");
    const double triangles = primitive_triangles(ctx, p);
    if (pos == p.attributes.end() || triangles == 0) continue;  // (points and lines are not read)
    const double vertices = accessor_count(ctx, pos->second);
    double per_vertex = 2 * sizeof(Vec3);  // positions, normals
    for (const auto& [name, size] : {std::pair<const char*, size_t>{"TEXCOORD_0", sizeof(Vec2)},
                                     {"TEXCOORD_1", sizeof(Vec2)},
                                     {"COLOR_0", sizeof(Rgb) + sizeof(float)},
                                     {"TANGENT", sizeof(Tangent)}})
      if (p.attributes.count(name)) per_vertex += double(size);
    const double arrays = vertices * per_vertex + triangles * 3 * sizeof(uint32_t);
    // A posed mesh keeps its rest arrays beside the scene's (gltf_animation); a skinned one
    // its object-space positions and normals, and 4 joints and weights a vertex.
    bytes += arrays * (1 + posed) + (skinned ? arrays + vertices * 8 * sizeof(float) : 0);
  }
  return bytes;
}

void check_gltf_budget(GltfContext& ctx, const std::vector<int>& roots) {
  Budget budget(ctx);
  double visits = 0, triangles = 0, meshes = 0, bytes = 0;
  for (int r : roots) {
    const Budget::Count c = budget.node(r, 0);
    visits += c.visits;
    triangles += c.triangles;
    meshes += c.meshes;
    bytes += c.bytes;
  }
  if (visits > kMaxGltfNodeVisits)
    ctx.fail("nodes", "the scene's node graph expands to " + count_text(visits) +
                          " node visits (a child listed more than once is expanded each time), over the limit of " +
                          count_text(kMaxGltfNodeVisits));
  if (meshes > kMaxGltfMeshCopies)
    ctx.fail("nodes", "the scene's node graph expands to " + count_text(meshes) +
                          " meshes (a mesh is copied at each visit of its node), over the limit of " +
                          count_text(kMaxGltfMeshCopies));
  if (triangles > kMaxGltfTriangles)
    ctx.fail("nodes", "the scene expands to " + count_text(triangles) +
                          " triangles (every node visit and instance counted), over the limit of " +
                          count_text(kMaxGltfTriangles));
  ctx.charge("nodes", "meshes", uint64_t(std::min(bytes, 1e18)));
}

}  // namespace tessera
