// glTF mesh primitives as our triangle meshes in world space (docs/gltf.md, Geometry):
// mode TRIANGLES, indexed or not; POSITION, NORMAL (by the inverse transpose) and
// TEXCOORD_0; a mirroring transform swaps the winding so geometric normals stay outward.
// Other primitive attributes (COLOR_0, TEXCOORD_1, JOINTS_0 and WEIGHTS_0 of skins, morph
// targets) and primitive extensions (KHR_draco_mesh_compression) are read here.
#pragma once

#include <string>
#include <vector>

#include "core/math/transform.h"
#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_materials.h"

namespace tessera {

struct GltfPrimitive {
  Mesh mesh;  // world space
  // The file's object-space positions and normals, 3 floats a vertex (normals empty when
  // the file has none), when asked for: an animated file poses them again.
  std::vector<float> positions, normals;
  bool mirrored = false;  // the transform's determinant is negative: mesh.indices' winding is swapped
};

// The primitives of meshes[index] placed by `world`, in the file's order, those without
// triangles left out; their materials made through `materials`. `node_el` names the node
// that refers to the mesh. `keep_object_space`: fill GltfPrimitive::positions and normals.
// Triangle strips and fans become triangles (in the specification's vertex order, so
// windings stay as authored); points and lines have no surface to render: skipped with a
// warning (the rest of the file renders).
std::vector<GltfPrimitive> read_gltf_mesh(GltfContext& ctx, GltfMaterials& materials, int index, const Mat4& world,
                                          const std::string& node_el, bool keep_object_space);

}  // namespace tessera
