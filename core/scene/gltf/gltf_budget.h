// The scene graph's budget, counted before anything is expanded. A node's children are
// visited once each time they are listed, so a 1 KB file whose nodes list a child twice,
// nested 30 deep, asks the walk for 2^30 visits (a "DAG bomb": memory, or with no meshes
// a core pinned for days). check_gltf_budget counts, per node once (memoised), the visits
// and triangles (EXT_mesh_gpu_instancing's instances included where they are copies, in a
// file with animations or a skinned node; real instances store the mesh once) that the walk from `roots`
// would make, from the declared accessor counts, and refuses the file naming the limit;
// cycles and depth are refused here too, before the walk can recurse into them.
#pragma once

#include <vector>

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

constexpr double kMaxGltfNodeVisits = 4 << 20;     // node visits of the expanded graph
constexpr double kMaxGltfTriangles = 100'000'000;  // triangles of the expanded graph
constexpr size_t kMaxGltfNodeDepth = 256;

void check_gltf_budget(const GltfContext& ctx, const std::vector<int>& roots);

}  // namespace tessera
