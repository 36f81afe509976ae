// Morph targets and skins (glTF 2.0, 3.7.2.2 and 3.8): how a mesh's object-space vertices
// are displaced by weighted targets and carried by the joints of a skeleton. The glTF
// loader applies them for the rest pose and pose_scene for every frame of an animation,
// once per pose on the path that builds the BVH: nothing here runs per ray.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/math/transform.h"
#include "core/math/vec.h"

namespace tessera {

struct MorphTargets {
  // Per target, a displacement per vertex; normals[t] is empty where target t has none.
  std::vector<std::vector<Vec3>> positions, normals;
  std::vector<double> weights;  // the weights shown without animation (the node's, else the mesh's)
  size_t count() const { return positions.size(); }
};

struct Skin {
  std::vector<uint32_t> joints;    // the joints' nodes (the loader's glTF nodes; a pose's node entries)
  std::vector<Mat4> inverse_bind;  // one per joint
  // Vertex i's influences are [first[i], first[i + 1]): a joint (index into `joints`) and a
  // weight each; a vertex's weights sum to 1. Any number of influences (JOINTS_0, _1, ...).
  std::vector<uint32_t> first, joint;
  std::vector<float> weight;
};

// Adds sum_t weights[t] x target t to `p` and `n` (object space; `n` may be empty: then
// only positions move). A weight vector shorter than the targets counts the rest as 0.
void apply_morph(const MorphTargets& m, const std::vector<double>& weights, std::vector<Vec3>& p, std::vector<Vec3>& n);

// Linear blend skinning: vertex i in world space is (sum_k w_k J_k) p_i, with J_k =
// joint_world[j_k] x inverse_bind[j_k]; normals by the blended matrix's inverse transpose.
// `p`, `n` object space (n may be empty); writes `out_p` and, where `n` is given, `out_n`.
void apply_skin(const Skin& s, const std::vector<Mat4>& joint_world, const std::vector<Vec3>& p,
                const std::vector<Vec3>& n, std::vector<Vec3>& out_p, std::vector<Vec3>& out_n);

}  // namespace tessera
