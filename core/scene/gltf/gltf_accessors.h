// glTF accessors read into plain arrays, every bound checked: the accessor against its
// buffer view (offset, stride, count), the view against its buffer, every index against
// the vertex count, every value for NaN or infinity. Every component type the
// specification allows is read (normalized integers scaled as it says), with byteStride
// and sparse accessors. (Compressed buffer views, EXT_meshopt_compression, would be
// decoded where a view is checked; KHR_mesh_quantization's types are already read.)
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

// The most values (elements x components) one accessor may hold: 1 GiB of floats. Checked
// with every view an accessor reads before its array is allocated.
constexpr uint64_t kMaxAccessorValues = uint64_t(1) << 28;

// accessors[index] as floats, `components` per element. `what` names the use in errors,
// e.g. "meshes[0].primitives[1] NORMAL".
std::vector<float> read_accessor_floats(const GltfContext& ctx, int index, int components, const std::string& what);

// accessors[index] as vertex indices (unsigned byte, short or int), each below
// `vertex_count`.
std::vector<uint32_t> read_accessor_indices(const GltfContext& ctx, int index, size_t vertex_count,
                                            const std::string& what);

}  // namespace tessera
