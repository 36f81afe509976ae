#include "core/scene/gltf/draco_shim.h"

#include <draco/compression/decode.h>

#include <memory>
#include <utility>

namespace tessera {

bool decode_draco_mesh(const char* data, size_t size, size_t max_points, DracoMesh* out, std::string* error) {
  draco::DecoderBuffer in;
  in.Init(data, size);
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&in);
  if (!decoded.ok()) {
    *error = decoded.status().error_msg_string();
    return false;
  }
  const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
  if (!mesh || mesh->num_points() > max_points) {
    *error = "no mesh, or more than " + std::to_string(max_points) + " points";
    return false;
  }
  out->points = mesh->num_points();
  out->indices.reserve(size_t(mesh->num_faces()) * 3);
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f)
    for (int k = 0; k < 3; ++k) out->indices.push_back(mesh->face(f)[k].value());
  for (int32_t i = 0; i < mesh->num_attributes(); ++i) {
    const draco::PointAttribute* a = mesh->attribute(i);
    const int comps = a->num_components();
    if (comps <= 0 || comps > 16) continue;
    DracoMesh::Attribute& dst = out->attributes[a->unique_id()];
    dst.components = comps;
    dst.values.resize(out->points * size_t(comps));
    for (size_t p = 0; p < out->points; ++p)
      if (!a->ConvertValue<float>(a->mapped_index(draco::PointIndex(uint32_t(p))), int8_t(comps),
                                  &dst.values[p * size_t(comps)])) {
        *error = "attribute " + std::to_string(a->unique_id()) + " does not convert to numbers";
        return false;
      }
  }
  return true;
}

}  // namespace tessera
