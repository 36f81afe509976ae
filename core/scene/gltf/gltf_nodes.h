// The node graph of the file's scene (docs/gltf.md, Geometry): the default scene (or scene
// 0; with no scenes, every node that is nobody's child), each node's local transform
// (a column-major matrix, or translation, rotation and scale) composed in double
// precision, and what the node carries placed by its world transform: its mesh
// (gltf_meshes), camera and KHR_lights_punctual light (gltf_lights_cameras). A cycle
// (a node its own ancestor) is refused naming the node; depth is limited to 256.
// (Node extensions, e.g. EXT_mesh_gpu_instancing, are read here.)
#pragma once

#include "core/scene/gltf/gltf_animation.h"
#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_materials.h"

namespace tessera {

// Adds to ctx.scene the meshes, lights and camera of the scene's nodes, in node order;
// while `animation` records, the hierarchy and what moves with each node too.
void add_gltf_nodes(GltfContext& ctx, GltfMaterials& materials, GltfAnimationBuilder& animation);

}  // namespace tessera
