#include "core/scene/gltf/gltf_skins.h"

#include <cmath>
#include <utility>

#include "core/scene/animation.h"
#include "core/scene/gltf/gltf_accessors.h"

namespace tessera {
namespace {

// A vertex's weights may miss 1 by the rounding of their stored type (8-bit weights of
// exporters sum to 253/255 - 257/255): within this they are rescaled to 1; beyond it the
// file is refused (a skin whose weights do not sum to 1 moves vertices off the skeleton).
constexpr double kWeightSumTolerance = 0.02;
constexpr size_t kMaxJoints = 1 << 16;

}  // namespace

std::vector<Vec3> as_vec3s(const std::vector<float>& f) {
  std::vector<Vec3> v(f.size() / 3);
  for (size_t i = 0; i < v.size(); ++i) v[i] = {f[3 * i], f[3 * i + 1], f[3 * i + 2]};
  return v;
}

std::shared_ptr<const MorphTargets> read_gltf_morph(GltfContext& ctx, const tinygltf::Primitive& prim,
                                                    const tinygltf::Mesh& mesh, const tinygltf::Node& node, size_t nv,
                                                    const std::string& el) {
  if (prim.targets.empty()) return nullptr;
  auto m = std::make_shared<MorphTargets>();
  // A target without POSITION holds nothing (apply_morph reads an empty list as zeros:
  // 2,000 empty targets of a 100k-vertex mesh held 2.4 GB of them), and the scene's
  // targets hold at most ctx.max_morph_values values together (as one accessor may).
  for (size_t t = 0; t < prim.targets.size(); ++t) {
    const std::string tel = el + " targets[" + std::to_string(t) + "]";
    std::vector<Vec3> dp, dn;
    for (const auto& [name, accessor] : prim.targets[t]) {
      if (name != "POSITION" && name != "NORMAL") continue;  // TANGENT: tangents are not read (docs/gltf.md)
      ctx.morph_values += 3 * uint64_t(nv);
      if (ctx.morph_values > ctx.max_morph_values)
        ctx.fail(tel, "the scene's morph targets would hold more than " + std::to_string(ctx.max_morph_values) +
                          " values (3 a vertex a target's POSITION or NORMAL), the limit");
      ctx.charge(tel, "morph targets", 3 * uint64_t(nv) * sizeof(float));
      std::vector<Vec3> d = as_vec3s(read_accessor_floats(ctx, accessor, 3, tel + " " + name));
      if (d.size() != nv)
        ctx.fail(tel, name + " has " + std::to_string(d.size()) + " elements for " + std::to_string(nv) + " vertices");
      (name == "POSITION" ? dp : dn) = std::move(d);
    }
    m->positions.push_back(std::move(dp));
    m->normals.push_back(std::move(dn));
  }
  const std::vector<double>& w = !node.weights.empty() ? node.weights : mesh.weights;
  if (!w.empty() && w.size() != m->count())
    ctx.fail(el, "weights has " + std::to_string(w.size()) + " numbers for " + std::to_string(m->count()) +
                     " morph targets");
  for (const double x : w)
    if (!std::isfinite(x)) ctx.fail(el, "a morph weight is not finite");
  m->weights = w;
  m->weights.resize(m->count(), 0.0);
  return m;
}

std::shared_ptr<const Skin> read_gltf_skin(const GltfContext& ctx, int index, const tinygltf::Primitive& prim,
                                           size_t nv, const std::string& el) {
  const std::string sel = "skins[" + std::to_string(index) + "]";
  if (index < 0 || size_t(index) >= ctx.model.skins.size()) ctx.fail(el, sel + " does not exist");
  const tinygltf::Skin& gs = ctx.model.skins[size_t(index)];
  auto s = std::make_shared<Skin>();
  if (gs.joints.empty()) ctx.fail(sel, "has no joints");
  if (gs.joints.size() > kMaxJoints) ctx.fail(sel, "has more than 65536 joints");
  for (const int j : gs.joints) {
    if (j < 0 || size_t(j) >= ctx.model.nodes.size())
      ctx.fail(sel, "joint node " + std::to_string(j) + " does not exist");
    s->joints.push_back(uint32_t(j));
  }
  s->inverse_bind.assign(s->joints.size(), Mat4());
  if (gs.inverseBindMatrices >= 0) {
    const std::vector<float> f = read_accessor_floats(ctx, gs.inverseBindMatrices, 16, sel + " inverseBindMatrices");
    if (f.size() / 16 < s->joints.size())
      ctx.fail(sel, "inverseBindMatrices has " + std::to_string(f.size() / 16) + " matrices for " +
                        std::to_string(s->joints.size()) + " joints");
    for (size_t j = 0; j < s->joints.size(); ++j) {
      std::array<double, 16> m{};
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = f[16 * j + size_t(c * 4 + r)];  // column-major
      s->inverse_bind[j] = Mat4::from_row_major(m);
    }
  }
  // Influences from every JOINTS_n / WEIGHTS_n pair the primitive has.
  std::vector<std::vector<float>> joints, weights;
  for (int set = 0;; ++set) {
    const std::string jn = "JOINTS_" + std::to_string(set), wn = "WEIGHTS_" + std::to_string(set);
    auto ja = prim.attributes.find(jn), wa = prim.attributes.find(wn);
    if (ja == prim.attributes.end() && wa == prim.attributes.end()) break;
    if (ja == prim.attributes.end() || wa == prim.attributes.end())
      ctx.fail(
          el, "has " + (ja == prim.attributes.end() ? wn : jn) + " without " + (ja == prim.attributes.end() ? jn : wn));
    joints.push_back(read_accessor_floats(ctx, ja->second, 4, el + " " + jn));
    weights.push_back(read_accessor_floats(ctx, wa->second, 4, el + " " + wn));
    if (joints.back().size() != 4 * nv || weights.back().size() != 4 * nv)
      ctx.fail(el, jn + " and " + wn + " must have one element per vertex (" + std::to_string(nv) + ")");
  }
  if (joints.empty()) ctx.fail(el, "is skinned by " + sel + " but has no JOINTS_0 and WEIGHTS_0");
  s->first.reserve(nv + 1);
  for (size_t v = 0; v < nv; ++v) {
    s->first.push_back(uint32_t(s->joint.size()));
    double sum = 0;
    for (size_t set = 0; set < joints.size(); ++set)
      for (size_t k = 0; k < 4; ++k) {
        const float w = weights[set][4 * v + k], j = joints[set][4 * v + k];
        if (w == 0) continue;
        if (w < 0) ctx.fail(el, "WEIGHTS_" + std::to_string(set) + " of vertex " + std::to_string(v) + " is negative");
        if (!(j >= 0 && j < float(s->joints.size())) || j != std::floor(j))
          ctx.fail(el, "JOINTS_" + std::to_string(set) + " of vertex " + std::to_string(v) + " names joint " +
                           std::to_string(j) + " of " + sel + "'s " + std::to_string(s->joints.size()));
        s->joint.push_back(uint32_t(j));
        s->weight.push_back(w);
        sum += w;
      }
    if (!(std::fabs(sum - 1) <= kWeightSumTolerance))
      ctx.fail(el, "the skin weights of vertex " + std::to_string(v) + " sum to " + std::to_string(sum) + ", not 1");
    for (size_t k = s->first.back(); k < s->weight.size(); ++k) s->weight[k] = float(s->weight[k] / sum);
  }
  s->first.push_back(uint32_t(s->joint.size()));
  return s;
}

void place_skinned_mesh(const GltfContext& ctx, Mesh& mesh, const Skin& skin, const MorphTargets* morph,
                        const std::vector<float>& p3, const std::vector<float>& n3, const std::vector<Mat4>& node_world,
                        const std::string& el) {
  std::vector<Vec3> p = as_vec3s(p3), n = as_vec3s(n3);
  if (morph) apply_morph(*morph, morph->weights, p, n);
  std::vector<Mat4> joints(skin.joints.size());
  for (size_t j = 0; j < joints.size(); ++j) joints[j] = node_world[skin.joints[j]];
  std::vector<Vec3> wn;
  apply_skin(skin, joints, p, n, mesh.positions, wn);
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    const Vec3 v = mesh.positions[i];
    if (!is_finite(v) || std::fabs(v.x) > Scene::kMaxCoordinate || std::fabs(v.y) > Scene::kMaxCoordinate ||
        std::fabs(v.z) > Scene::kMaxCoordinate)
      ctx.fail(el, "skinned vertex " + std::to_string(i) + " is not finite or outside +-1e12");
  }
  if (!wn.empty()) mesh.normals = std::move(wn);
}

GltfTrs gltf_trs(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el) {
  GltfTrs x;
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

Mat4 gltf_local_matrix(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el) {
  if (!n.matrix.empty()) {
    if (n.matrix.size() != 16) ctx.fail(el, "matrix needs 16 numbers");
    std::array<double, 16> m{};
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = n.matrix[size_t(c * 4 + r)];  // glTF is column-major
    return Mat4::from_row_major(m);
  }
  const GltfTrs x = gltf_trs(ctx, n, el);
  return trs_matrix(x.t, x.r, x.s);
}

std::vector<Mat4> gltf_rest_worlds(const GltfContext& ctx) {
  const auto& nodes = ctx.model.nodes;
  std::vector<int> parent(nodes.size(), -1);
  for (size_t i = 0; i < nodes.size(); ++i)
    for (const int c : nodes[i].children)
      if (c >= 0 && size_t(c) < nodes.size() && parent[size_t(c)] < 0) parent[size_t(c)] = int(i);
  std::vector<Mat4> world(nodes.size());
  std::vector<char> done(nodes.size(), 0);
  for (size_t i = 0; i < nodes.size(); ++i) {
    std::vector<size_t> chain;  // i and its ancestors not yet done, nearest first
    for (int k = int(i); k >= 0 && !done[size_t(k)] && chain.size() <= nodes.size(); k = parent[size_t(k)])
      chain.push_back(size_t(k));
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      const size_t k = *it;
      const Mat4 local = gltf_local_matrix(ctx, nodes[k], "nodes[" + std::to_string(k) + "]");
      world[k] = parent[k] >= 0 ? world[size_t(parent[k])] * local : local;
      done[k] = 1;
    }
  }
  return world;
}

}  // namespace tessera
