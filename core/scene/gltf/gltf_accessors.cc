#include "core/scene/gltf/gltf_accessors.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

namespace tessera {
namespace {

// Where `count` elements of `comps` components of `type` start in a buffer view, after
// checking that every byte of them lies inside the view and the view inside its buffer.
struct ViewSpan {
  const unsigned char* base;
  size_t stride;
  int csize;
};
ViewSpan checked_view(const GltfContext& ctx, int view_index, size_t offset, int type, size_t count, int comps,
                      const std::string& el) {
  const tinygltf::Model& model = ctx.model;
  if (view_index < 0 || size_t(view_index) >= model.bufferViews.size())
    ctx.fail(el, "bufferView " + std::to_string(view_index) + " does not exist");
  const tinygltf::BufferView& v = model.bufferViews[size_t(view_index)];
  if (v.buffer < 0 || size_t(v.buffer) >= model.buffers.size())
    ctx.fail(el, "buffer " + std::to_string(v.buffer) + " does not exist");
  const std::vector<unsigned char>& data = model.buffers[size_t(v.buffer)].data;
  const int csize = tinygltf::GetComponentSizeInBytes(uint32_t(type));
  if (csize <= 0) ctx.fail(el, "unknown component type " + std::to_string(type));
  const uint64_t elem = uint64_t(csize) * uint64_t(comps);
  const uint64_t stride = v.byteStride ? v.byteStride : elem;
  if (stride < elem) ctx.fail(el, "byteStride " + std::to_string(v.byteStride) + " is smaller than an element");
  if (v.byteOffset > data.size() || v.byteLength > data.size() - v.byteOffset)  // (no sum: it could wrap)
    ctx.fail(el, "bufferView " + std::to_string(view_index) + " runs past the end of its buffer (" +
                     std::to_string(v.byteOffset + v.byteLength) + " > " + std::to_string(data.size()) + " bytes)");
  // (Division, not multiplication: a count near 2^64 must not wrap into a small size.)
  if (count > 0 && (uint64_t(offset) > v.byteLength || elem > v.byteLength - uint64_t(offset) ||
                    uint64_t(count - 1) > (v.byteLength - uint64_t(offset) - elem) / stride))
    ctx.fail(el, "byteOffset " + std::to_string(offset) + " with " + std::to_string(count) +
                     " elements runs past the end of bufferView " + std::to_string(view_index));
  return {data.data() + v.byteOffset + offset, size_t(stride), csize};
}

// `count` elements of a view checked_view() gave for them, as floats.
void read_view(const GltfContext& ctx, const ViewSpan& view, int type, bool normalized, size_t count, int comps,
               const std::string& el, float* out) {
  const auto [base, stride, csize] = view;
  for (size_t i = 0; i < count; ++i)
    for (int c = 0; c < comps; ++c) {
      const unsigned char* p = base + i * stride + size_t(c) * size_t(csize);
      float f = 0;
      switch (type) {
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          int8_t x;
          std::memcpy(&x, p, 1);
          f = normalized ? std::max(float(x) / 127.0f, -1.0f) : float(x);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
          f = normalized ? float(*p) / 255.0f : float(*p);
          break;
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
          int16_t x;
          std::memcpy(&x, p, 2);
          f = normalized ? std::max(float(x) / 32767.0f, -1.0f) : float(x);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          uint16_t x;
          std::memcpy(&x, p, 2);
          f = normalized ? float(x) / 65535.0f : float(x);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
          uint32_t x;
          std::memcpy(&x, p, 4);
          f = float(x);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
          std::memcpy(&f, p, 4);
          break;
        default:
          ctx.fail(el, "component type " + std::to_string(type) + " is not allowed here");
      }
      out[i * size_t(comps) + size_t(c)] = f;
    }
}

// glTF's index types: unsigned byte, short or int.
bool unsigned_index_type(int type) {
  return type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE || type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
         type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
}

// `count` unsigned integers of `type` (byte, short or int) from a view, checked as above.
std::vector<uint32_t> read_unsigned(const GltfContext& ctx, int view_index, size_t offset, int type, size_t count,
                                    const std::string& el) {
  const auto [base, stride, csize] = checked_view(ctx, view_index, offset, type, count, 1, el);
  std::vector<uint32_t> out(count);
  for (size_t i = 0; i < count; ++i) {
    uint32_t x = 0;
    std::memcpy(&x, base + i * stride, size_t(csize));  // (little-endian, as glTF)
    out[i] = x;
  }
  return out;
}

// accessors[index]; one that does not exist is refused naming its use.
const tinygltf::Accessor& accessor_at(const GltfContext& ctx, int index, const std::string& what) {
  if (index < 0 || size_t(index) >= ctx.model.accessors.size())
    ctx.fail(what, "accessor " + std::to_string(index) + " does not exist");
  return ctx.model.accessors[size_t(index)];
}

}  // namespace

std::vector<float> read_accessor_floats(const GltfContext& ctx, int index, int want_components,
                                        const std::string& what) {
  const std::string el = "accessors[" + std::to_string(index) + "] (" + what + ")";
  const tinygltf::Accessor& a = accessor_at(ctx, index, what);
  const int comps = tinygltf::GetNumComponentsInType(uint32_t(a.type));
  if (comps != want_components)
    ctx.fail(el, "has " + std::to_string(comps) + " components, expected " + std::to_string(want_components));
  if (uint64_t(a.count) > kMaxAccessorValues / uint64_t(comps))  // (divided: a huge count must not wrap)
    ctx.fail(el, "count " + std::to_string(a.count) + " x " + std::to_string(comps) +
                     " components is over the limit of " + std::to_string(kMaxAccessorValues) +
                     " values an accessor may hold");
  // Every view checked before anything is allocated: a 452-byte file declaring 268 M
  // vertices over a 36-byte view made 3 GB before its refusal.
  std::optional<ViewSpan> view, sparse_values;
  if (a.bufferView >= 0) view = checked_view(ctx, a.bufferView, a.byteOffset, a.componentType, a.count, comps, el);
  std::vector<uint32_t> sparse_indices;
  if (a.sparse.isSparse) {
    const auto& sp = a.sparse;
    if (sp.count < 0 || size_t(sp.count) > a.count) ctx.fail(el, "sparse count out of range");
    if (!unsigned_index_type(sp.indices.componentType))
      ctx.fail(el + " sparse indices", "must be unsigned byte, short or int");
    sparse_values = checked_view(ctx, sp.values.bufferView, size_t(std::max(0, sp.values.byteOffset)), a.componentType,
                                 size_t(sp.count), comps, el + " sparse values");
    // As integers, not through read_view's floats, which lose precision past 2^24.
    sparse_indices = read_unsigned(ctx, sp.indices.bufferView, size_t(std::max(0, sp.indices.byteOffset)),
                                   sp.indices.componentType, size_t(sp.count), el + " sparse indices");
    for (const uint32_t i : sparse_indices)
      if (i >= a.count) ctx.fail(el, "sparse index " + std::to_string(i) + " out of range");
  }
  std::vector<float> out(a.count * size_t(comps), 0.0f);
  if (view) read_view(ctx, *view, a.componentType, a.normalized, a.count, comps, el, out.data());
  if (sparse_values) {
    std::vector<float> val(sparse_indices.size() * size_t(comps));
    read_view(ctx, *sparse_values, a.componentType, a.normalized, sparse_indices.size(), comps, el + " sparse values",
              val.data());
    for (size_t k = 0; k < sparse_indices.size(); ++k)
      std::copy(val.begin() + long(k * comps), val.begin() + long((k + 1) * comps),
                out.begin() + long(size_t(sparse_indices[k]) * comps));
  }
  for (float v : out)
    if (!std::isfinite(v)) ctx.fail(el, "contains a NaN or infinite value");
  return out;
}

std::vector<uint32_t> read_accessor_indices(const GltfContext& ctx, int index, size_t vertex_count,
                                            const std::string& what) {
  const std::string el = "accessors[" + std::to_string(index) + "] (" + what + ")";
  const tinygltf::Accessor& a = accessor_at(ctx, index, what);
  if (!unsigned_index_type(a.componentType)) ctx.fail(el, "indices must be unsigned byte, short or int");
  if (a.bufferView < 0) ctx.fail(el, "indices need a bufferView");
  // Read as integers, not through read_view's floats, which lose precision past 2^24.
  std::vector<uint32_t> out = read_unsigned(ctx, a.bufferView, a.byteOffset, a.componentType, a.count, el);
  for (const uint32_t x : out)
    if (x >= vertex_count)
      ctx.fail(el, "index " + std::to_string(x) + " out of range (" + std::to_string(vertex_count) + " vertices)");
  return out;
}

}  // namespace tessera
