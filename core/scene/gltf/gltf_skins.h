// glTF morph targets and skins read into core/scene/deform.h's model, every value checked:
// target counts against the vertex count, weights against the target count, joint indices
// against the skin's joints, each vertex's weights summing to 1, inverse bind matrices
// (MAT4, one per joint). docs/gltf.md, Morph targets and skins.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "core/scene/deform.h"
#include "core/scene/gltf/gltf_context.h"

namespace tessera {

// 3 floats a vertex (as accessors are read) as vectors.
std::vector<Vec3> as_vec3s(const std::vector<float>& f);

// The primitive's morph targets with the weights shown without animation (the node's,
// else the mesh's); null when it has none. `nv`: its vertex count.
std::shared_ptr<const MorphTargets> read_gltf_morph(GltfContext& ctx, const tinygltf::Primitive& prim,
                                                    const tinygltf::Mesh& mesh, const tinygltf::Node& node, size_t nv,
                                                    const std::string& el);

// skins[skin] bound to the primitive's JOINTS_n / WEIGHTS_n (every set the primitive has);
// joints are glTF node indices.
std::shared_ptr<const Skin> read_gltf_skin(const GltfContext& ctx, int skin, const tinygltf::Primitive& prim, size_t nv,
                                           const std::string& el);

// Places a skinned mesh in world space: the file's object-space vertices `p3` and normals
// `n3` (3 floats each; n3 may be empty), moved by the morph targets' shown weights (morph
// may be null), then skinned with the joints at `node_world`. The node's own transform is
// ignored, as the specification says. Refuses vertices that end up non-finite or out of
// range, naming `el`.
void place_skinned_mesh(const GltfContext& ctx, Mesh& mesh, const Skin& skin, const MorphTargets* morph,
                        const std::vector<float>& p3, const std::vector<float>& n3, const std::vector<Mat4>& node_world,
                        const std::string& el);

// Every node's world transform in the file's rest pose (through its parents; a node with
// two parents takes the first).
std::vector<Mat4> gltf_rest_worlds(const GltfContext& ctx);

// A node's translation, rotation and scale (glTF's defaults where absent), checked.
struct GltfTrs {
  std::array<double, 3> t{0, 0, 0}, s{1, 1, 1};
  std::array<double, 4> r{0, 0, 0, 1};
};
GltfTrs gltf_trs(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el);

// The node's local transform (matrix, or translation x rotation x scale), checked.
Mat4 gltf_local_matrix(const GltfContext& ctx, const tinygltf::Node& n, const std::string& el);

}  // namespace tessera
