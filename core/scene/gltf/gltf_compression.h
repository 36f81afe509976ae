// Compressed glTF geometry decoded with the Debian libraries, right after parsing and
// before anything reads an accessor: EXT_meshopt_compression buffer views
// (libmeshoptimizer: vertex and index codecs, octahedral / quaternion / exponential
// filters) and KHR_draco_mesh_compression primitives (libdraco). Each decoded view or
// attribute becomes an ordinary buffer view of the model, so every later unit (accessors,
// meshes, animation) reads it as if the file were uncompressed, with every check it makes.
// A stream that does not decode, or decodes to other counts than the file declares, is
// refused naming the view or primitive.
#pragma once

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

void decode_gltf_compression(GltfContext& ctx);

}  // namespace tessera
