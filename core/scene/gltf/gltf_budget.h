// The scene graph's budget, counted before anything is expanded. A node's children are
// visited once each time they are listed, so a 1 KB file whose nodes list a child twice,
// nested 30 deep, asks the walk for 2^30 visits (a "DAG bomb": memory, or with no meshes
// a core pinned for days). check_gltf_budget counts, per node once (memoised), the visits
// meshes and triangles (EXT_mesh_gpu_instancing's instances included where they are copies, in a
// file with animations or a skinned node; real instances store the mesh once) that the walk from `roots`
// would make, from the declared accessor counts, and refuses the file naming the limit;
// cycles and depth are refused here too, before the walk can recurse into them. The
// expanded meshes' arrays are charged to the load's memory bound (GltfContext::charge).
#pragma once

#include <vector>

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

// Node visits of the expanded graph. (4 M took 11 s under AddressSanitizer: a fuzzer's
// timeout; ~0.5 s in a release build. A real scene has far fewer.)
constexpr double kMaxGltfNodeVisits = 1 << 20;
constexpr double kMaxGltfTriangles = 100'000'000;  // triangles of the expanded graph
// Meshes of the expanded graph (a primitive at each visit of its node): each copy has
// arrays of its own, ~1 KB at least, so a 1 KB file listing a one-triangle mesh's node
// twice, 21 deep, held 2 GB and took 15 s to check.
constexpr double kMaxGltfMeshCopies = 1 << 20;
constexpr size_t kMaxGltfNodeDepth = 256;

void check_gltf_budget(GltfContext& ctx, const std::vector<int>& roots);
// The bytes mesh `mesh` holds once read (scene.h's Mesh: per vertex its position and
// normal and the texture coordinates, colours and tangents the file gives; 3 indices a
// triangle; points and lines not at all), from its declared counts; `posed`: in a file
// with animations, `skinned`: at a skinned node, which keep more.
double gltf_mesh_bytes(const GltfContext& ctx, int mesh, bool posed, bool skinned);

}  // namespace tessera
