// glTF materials as ours (docs/gltf.md, Materials): metallic-roughness as Material::kPbr
// with KHR_materials_transmission, _ior, _volume and _emissive_strength; emission adds to
// the material's reflection. Factors outside the specification's ranges are refused
// naming the material; what is not rendered (alphaMode, transmissionTexture) is warned.
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_textures.h"

namespace tessera {

class GltfMaterials {
 public:
  explicit GltfMaterials(GltfContext& ctx) : ctx_(ctx), textures_(ctx) {}

  // The scene's material for materials[index] (-1: the specification's default, white,
  // metallic 1, roughness 1), made the first time a primitive uses it.
  uint32_t material(int index);

 private:
  TextureRef ext_texture(const tinygltf::ExtensionMap& ex, const char* ext, const char* key, bool srgb,
                         const std::string& el);
  void read_specular(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m);
  void read_clearcoat(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m);
  void read_sheen(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m);

  GltfContext& ctx_;
  GltfTextures textures_;
  std::map<int, uint32_t> made_;  // glTF material index -> scene material
};

}  // namespace tessera
