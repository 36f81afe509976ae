// glTF mesh primitives as our triangle meshes in world space (docs/gltf.md, Geometry):
// mode TRIANGLES, indexed or not; POSITION, NORMAL (by the inverse transpose) and
// TEXCOORD_0; a mirroring transform swaps the winding so geometric normals stay outward.
// COLOR_0 and TEXCOORD_1; morph targets and skins (gltf_skins.h) are read here too.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/math/transform.h"
#include "core/scene/deform.h"
#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_materials.h"

namespace tessera {

struct GltfPrimitive {
  Mesh mesh;  // world space (a skinned one: placed by add_gltf_nodes once every joint is known)
  // The file's object-space positions and normals, 3 floats a vertex (normals empty when
  // the file has none), before any morph target, when asked for or skinned: an animated
  // file poses them again, a skin places them.
  std::vector<float> positions, normals;
  std::vector<float> tangents;  // likewise, 4 floats a vertex (empty unless mesh.tangents)
  // The transform's determinant is negative: mesh.indices' winding is swapped (never for a
  // skinned mesh, which follows its joints and keeps the file's winding).
  bool mirrored = false;
  std::shared_ptr<const MorphTargets> morph;  // null without targets
  std::shared_ptr<const Skin> skin;           // null unless the node has a skin
};

// The primitives of meshes[index] placed by `world`, in the file's order, those without
// triangles left out; their materials made through `materials`. `node_el` names the node
// that refers to the mesh. `keep_object_space`: fill GltfPrimitive::positions and normals.
// Triangle strips and fans become triangles (in the specification's vertex order, so
// windings stay as authored); points and lines have no surface to render: skipped with a
// warning (the rest of the file renders).
// Morph targets are applied with the node's (else the mesh's) weights.
std::vector<GltfPrimitive> read_gltf_mesh(GltfContext& ctx, GltfMaterials& materials, const tinygltf::Node& node,
                                          const Mat4& world, const std::string& node_el, bool keep_object_space);

}  // namespace tessera
