#include "core/scene/gltf/gltf_compression.h"

#include <meshoptimizer.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/scene/gltf/draco_shim.h"

namespace tessera {
namespace {

constexpr uint64_t kMaxDecodedBytes = uint64_t(1) << 30;       // a view's, as a buffer's limit
constexpr uint64_t kMaxDecodedTotalBytes = uint64_t(4) << 30;  // every view's together
constexpr uint64_t kMaxDracoPoints = uint64_t(1) << 28;

// An integer field of an extension object, `fallback` when absent; refused when negative
// or not an integer.
uint64_t field(const GltfContext& ctx, const tinygltf::Value& ext, const char* key, const std::string& el,
               int64_t fallback = -1) {
  if (!ext.Has(key)) {
    if (fallback < 0) ctx.fail(el, std::string("has no ") + key);
    return uint64_t(fallback);
  }
  const tinygltf::Value& v = ext.Get(key);
  // (Range first: converting a double beyond 2^63 to an integer is undefined, fuzz_gltf
  // found 3e116.)
  const double d = v.IsNumber() ? v.GetNumberAsDouble() : -1;
  if (!(d >= 0 && d < 0x1p63) || d != std::floor(d)) ctx.fail(el, std::string(key) + " is not a non-negative integer");
  return uint64_t(d);
}
std::string text(const tinygltf::Value& ext, const char* key, const char* fallback) {
  return ext.Has(key) && ext.Get(key).IsString() ? ext.Get(key).Get<std::string>() : fallback;
}

// Appends `bytes` as a new buffer; returns its index.
int add_buffer(tinygltf::Model& model, std::vector<unsigned char> bytes) {
  tinygltf::Buffer b;
  b.data = std::move(bytes);
  model.buffers.push_back(std::move(b));
  return int(model.buffers.size() - 1);
}

// `decoded`: what the views before it decoded to, this one's added.
void decode_meshopt_view(GltfContext& ctx, size_t index, uint64_t* decoded) {
  tinygltf::BufferView& view = ctx.model.bufferViews[index];
  const tinygltf::Value& ext = view.extensions.at("EXT_meshopt_compression");
  const std::string el = "bufferViews[" + std::to_string(index) + "] EXT_meshopt_compression";
  if (!ext.IsObject()) ctx.fail(el, "is not an object");
  const uint64_t buffer = field(ctx, ext, "buffer", el), offset = field(ctx, ext, "byteOffset", el, 0),
                 length = field(ctx, ext, "byteLength", el), stride = field(ctx, ext, "byteStride", el),
                 count = field(ctx, ext, "count", el);
  const std::string mode = text(ext, "mode", ""), filter = text(ext, "filter", "NONE");
  if (buffer >= ctx.model.buffers.size()) ctx.fail(el, "buffer " + std::to_string(buffer) + " does not exist");
  const std::vector<unsigned char>& src = ctx.model.buffers[buffer].data;
  if (offset > src.size() || length > src.size() - offset)
    ctx.fail(el, "byteOffset + byteLength (" + std::to_string(offset + length) + ") runs past buffer " +
                     std::to_string(buffer) + " (" + std::to_string(src.size()) + " bytes)");
  if (stride == 0 || stride > 256 || stride % (mode == "ATTRIBUTES" ? 4 : 1))
    ctx.fail(el, "byteStride " + std::to_string(stride) + " is not allowed for mode " + mode);
  if (count > kMaxDecodedBytes / stride) ctx.fail(el, "decodes to more than the 1 GiB limit");
  *decoded += count * stride;
  if (*decoded > kMaxDecodedTotalBytes)
    ctx.fail(el, "the scene's compressed views decode to more than the 4 GiB limit together");
  ctx.charge(el, "decoded views", count * stride);
  std::vector<unsigned char> out(count * stride);
  const unsigned char* in = src.data() + offset;
  int rc = -1;
  if (mode == "ATTRIBUTES") {
    rc = meshopt_decodeVertexBuffer(out.data(), count, stride, in, length);
  } else if (mode == "TRIANGLES" || mode == "INDICES") {
    if (stride != 2 && stride != 4) ctx.fail(el, "index byteStride must be 2 or 4");
    if (mode == "TRIANGLES" && count % 3)
      ctx.fail(el, "TRIANGLES count " + std::to_string(count) + " is not a multiple of 3");
    rc = mode == "TRIANGLES" ? meshopt_decodeIndexBuffer(out.data(), count, stride, in, length)
                             : meshopt_decodeIndexSequence(out.data(), count, stride, in, length);
  } else {
    ctx.fail(el, "mode '" + mode + "' is not ATTRIBUTES, TRIANGLES or INDICES");
  }
  if (rc != 0)
    ctx.fail(el, "the compressed data is damaged or shorter than its count says (meshoptimizer error " +
                     std::to_string(rc) + ")");
  if (filter == "OCTAHEDRAL") {
    if (stride != 4 && stride != 8) ctx.fail(el, "OCTAHEDRAL needs byteStride 4 or 8");
    meshopt_decodeFilterOct(out.data(), count, stride);
  } else if (filter == "QUATERNION") {
    if (stride != 8) ctx.fail(el, "QUATERNION needs byteStride 8");
    meshopt_decodeFilterQuat(out.data(), count, stride);
  } else if (filter == "EXPONENTIAL") {
    meshopt_decodeFilterExp(out.data(), count, stride);
  } else if (filter != "NONE") {
    ctx.fail(el, "filter '" + filter + "' is not NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL");
  }
  view.buffer = add_buffer(ctx.model, std::move(out));
  view.byteOffset = 0;
  view.byteLength = count * stride;
  view.byteStride = mode == "ATTRIBUTES" ? stride : 0;
  view.extensions.erase("EXT_meshopt_compression");
}

// Points accessors[index] at `bytes` (`count` elements of its type, `component_type`
// each), replacing what it had.
void set_accessor(tinygltf::Model& model, int index, std::vector<unsigned char> bytes, int component_type,
                  size_t count) {
  tinygltf::BufferView view;
  view.byteLength = bytes.size();
  view.buffer = add_buffer(model, std::move(bytes));
  model.bufferViews.push_back(view);
  tinygltf::Accessor& a = model.accessors[size_t(index)];
  a.bufferView = int(model.bufferViews.size() - 1);
  a.byteOffset = 0;
  a.componentType = component_type;
  a.normalized = false;
  a.count = count;
  a.sparse.isSparse = false;
  a.sparse.count = 0;
}
template <typename T>
std::vector<unsigned char> as_bytes(const std::vector<T>& v) {
  std::vector<unsigned char> b(v.size() * sizeof(T));
  std::memcpy(b.data(), v.data(), b.size());
  return b;
}

void decode_draco_primitive(GltfContext& ctx, tinygltf::Primitive& prim, const std::string& el) {
  const tinygltf::Value& ext = prim.extensions.at("KHR_draco_mesh_compression");
  const std::string xel = el + " KHR_draco_mesh_compression";
  if (!ext.IsObject()) ctx.fail(xel, "is not an object");
  const uint64_t view_index = field(ctx, ext, "bufferView", xel);
  if (view_index >= ctx.model.bufferViews.size())
    ctx.fail(xel, "bufferView " + std::to_string(view_index) + " does not exist");
  const tinygltf::BufferView& view = ctx.model.bufferViews[view_index];
  if (view.buffer < 0 || size_t(view.buffer) >= ctx.model.buffers.size() ||
      view.byteOffset > ctx.model.buffers[size_t(view.buffer)].data.size() ||
      view.byteLength > ctx.model.buffers[size_t(view.buffer)].data.size() - view.byteOffset)
    ctx.fail(xel, "bufferView " + std::to_string(view_index) + " runs past its buffer");
  DracoMesh mesh;
  std::string why;
  if (!decode_draco_mesh(
          reinterpret_cast<const char*>(ctx.model.buffers[size_t(view.buffer)].data.data() + view.byteOffset),
          view.byteLength, kMaxDracoPoints, &mesh, &why))
    ctx.fail(xel, "the Draco data does not decode (" + why + ")");
  if (!ext.Has("attributes") || !ext.Get("attributes").IsObject()) ctx.fail(xel, "has no attributes");
  const tinygltf::Value& attrs = ext.Get("attributes");
  for (const std::string& name : attrs.Keys()) {
    auto it = prim.attributes.find(name);
    if (it == prim.attributes.end()) continue;  // the extension may carry attributes the primitive does not use
    const int accessor = it->second;
    if (accessor < 0 || size_t(accessor) >= ctx.model.accessors.size())
      ctx.fail(xel, name + " accessor " + std::to_string(accessor) + " does not exist");
    tinygltf::Accessor& acc = ctx.model.accessors[size_t(accessor)];
    const uint64_t id = field(ctx, attrs, name.c_str(), xel);
    auto a = mesh.attributes.find(uint32_t(id));
    if (a == mesh.attributes.end())
      ctx.fail(xel, name + " names Draco attribute " + std::to_string(id) + ", which the data lacks");
    const int comps = tinygltf::GetNumComponentsInType(uint32_t(acc.type));
    if (comps <= 0 || a->second.components < comps)
      ctx.fail(xel, name + " has " + std::to_string(a->second.components) +
                        " components in the Draco data, the accessor " + std::to_string(comps));
    if (acc.count != mesh.points)
      ctx.fail(xel, name + ": the Draco data has " + std::to_string(mesh.points) + " points, accessors[" +
                        std::to_string(accessor) + "] says " + std::to_string(acc.count));
    ctx.charge(xel, "decoded views", uint64_t(mesh.points) * uint64_t(comps) * sizeof(float));
    std::vector<float> values(mesh.points * size_t(comps));
    for (size_t p = 0; p < mesh.points; ++p)
      for (int c = 0; c < comps; ++c)
        values[p * size_t(comps) + size_t(c)] = a->second.values[p * size_t(a->second.components) + size_t(c)];
    set_accessor(ctx.model, accessor, as_bytes(values), TINYGLTF_COMPONENT_TYPE_FLOAT, mesh.points);
  }
  if (prim.indices >= 0) {
    if (size_t(prim.indices) >= ctx.model.accessors.size()) ctx.fail(xel, "the indices accessor does not exist");
    if (ctx.model.accessors[size_t(prim.indices)].count != mesh.indices.size())
      ctx.fail(xel, "the Draco data has " + std::to_string(mesh.indices.size()) + " indices, the accessor says " +
                        std::to_string(ctx.model.accessors[size_t(prim.indices)].count));
    ctx.charge(xel, "decoded views", uint64_t(mesh.indices.size()) * sizeof(uint32_t));
    set_accessor(ctx.model, prim.indices, as_bytes(mesh.indices), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                 mesh.indices.size());
  }
  prim.extensions.erase("KHR_draco_mesh_compression");
}

}  // namespace

void decode_gltf_compression(GltfContext& ctx) {
  // Only views an accessor reads are decoded, within a budget for all of them: views
  // nothing uses were decoded too, and 40 of them sharing 1 MB of compressed bytes held
  // 2.6 GB.
  std::set<int> used;
  for (const tinygltf::Accessor& a : ctx.model.accessors) {
    used.insert(a.bufferView);
    if (a.sparse.isSparse) used.insert({a.sparse.indices.bufferView, a.sparse.values.bufferView});
  }
  uint64_t decoded = 0;
  for (size_t i = 0; i < ctx.model.bufferViews.size(); ++i)
    if (ctx.model.bufferViews[i].extensions.count("EXT_meshopt_compression") && used.count(int(i)))
      decode_meshopt_view(ctx, i, &decoded);
  for (size_t m = 0; m < ctx.model.meshes.size(); ++m)
    for (size_t p = 0; p < ctx.model.meshes[m].primitives.size(); ++p) {
      tinygltf::Primitive& prim = ctx.model.meshes[m].primitives[p];
      if (prim.extensions.count("KHR_draco_mesh_compression"))
        decode_draco_primitive(ctx, prim, "meshes[" + std::to_string(m) + "].primitives[" + std::to_string(p) + "]");
    }
}

}  // namespace tessera
