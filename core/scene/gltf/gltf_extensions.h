// The glTF extensions Tessera reads (docs/gltf.md, Extensions). One in extensionsRequired
// that is not here refuses the file (gltf_prechecks.cc); one only in extensionsUsed is a
// warning (gltf_document.cc). Supporting another: its name here, and its reading in the
// unit of what it extends: gltf_materials.cc (KHR_materials_*), gltf_textures.cc
// (KHR_texture_transform), gltf_lights_cameras.cc (KHR_lights_punctual), gltf_meshes.cc
// (primitives: KHR_draco_mesh_compression), gltf_accessors.cc (buffer views and component
// types: EXT_meshopt_compression, KHR_mesh_quantization), gltf_nodes.cc (node
// extensions: EXT_mesh_gpu_instancing).
#pragma once

#include <set>
#include <string>
#include <utility>

namespace tessera {

inline bool gltf_extension_supported(const std::string& name) {
  static const std::set<std::string> kSupported = {
      "KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume",
      "KHR_materials_emissive_strength", "KHR_texture_transform", "KHR_materials_specular", "KHR_materials_clearcoat",
      "KHR_materials_sheen",
      // Integer attributes: every accessor is read with the component types and
      // normalization the core allows for any attribute (gltf_accessors.cc).
      "KHR_mesh_quantization",
      // Instances are copied into the scene (gltf_nodes.cc): memory grows with their count.
      "EXT_mesh_gpu_instancing",
      // Decoded after parsing (gltf_compression.cc) with libmeshoptimizer and libdraco.
      "EXT_meshopt_compression", "KHR_draco_mesh_compression",
      // WebP images through libwebp (gltf_textures.cc).
      "EXT_texture_webp",
      // Metadata (XMP): nothing to render, so nothing is lost by not reading it.
      "KHR_xmp_json_ld"};
  return kSupported.count(name) > 0;
}

// Texture extensions that name an image in a format we cannot decode (no Debian library
// for KTX2; stb reads no AVIF): each texture's PNG or JPEG fallback `source` is used, with a warning; a texture
// without one, or a file requiring the extension, is refused saying so.
inline constexpr std::pair<const char*, const char*> kGltfImageFormatExtensions[] = {
    {"KHR_texture_basisu", "KTX2 / Basis Universal"}, {"EXT_texture_avif", "AVIF"}};
// The image format `ext` names (one of the above), or null.
inline const char* gltf_undecodable_format(const std::string& ext) {
  for (const auto& [name, format] : kGltfImageFormatExtensions)
    if (ext == name) return format;
  return nullptr;
}

}  // namespace tessera
