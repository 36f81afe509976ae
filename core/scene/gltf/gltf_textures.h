// glTF textures as materials use them (docs/gltf.md, Materials): a textureInfo with its
// KHR_texture_transform, the texture's image decoded (PNG or JPEG, to RGBA 8-bit) the
// first time a material uses it, sRGB or linear as the slot wants, its sampler's wrap
// modes. An image no material uses is never decoded: a broken one costs nothing and
// refuses nothing, as in viewers.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

class GltfTextures {
 public:
  explicit GltfTextures(GltfContext& ctx) : ctx_(ctx) {}

  // A material's textureInfo: textures[index] (none for index -1), decoded into the
  // scene's textures once per colour space, and its KHR_texture_transform. A texCoord
  // other than 0 is a warning (only TEXCOORD_0 is read). `el` names the material, `what`
  // the slot ("baseColorTexture").
  TextureRef texture_ref(int index, int tex_coord, const tinygltf::ExtensionMap& extensions, bool srgb,
                         const std::string& el, const std::string& what);

 private:
  struct Pixels {
    int width = 0, height = 0;
    std::shared_ptr<const std::vector<uint8_t>> rgba;  // 4 bytes a texel
    bool translucent = false;                          // some alpha byte is not 255
  };
  int load_texture(int index, const std::string& el, bool srgb);
  const Pixels& image_pixels(int index, const std::string& el);
  tinygltf::Image& decode_image(int index);
  tinygltf::Image& decode_webp(tinygltf::Image& img, const std::string& el);

  GltfContext& ctx_;
  std::map<int, int> loaded_;  // 2 x texture index + sRGB -> scene texture
  // The same image in the same colour space with the same sampling (source, sRGB, wrap s,
  // wrap t, nearest) -> scene texture: textures that differ only in their index share it
  // (13 texture slots naming one 4096^2 image held 13 copies, 2.4 GB).
  std::map<std::tuple<int, bool, int, int, bool>, int> same_;
  std::map<int, Pixels> pixels_;  // image index -> its pixels
  uint64_t texels_ = 0;           // of the scene's images, against ctx_.max_scene_texels
};

// tinygltf's image loader (TinyGLTF::SetImageLoader): keeps each image's encoded bytes
// for GltfTextures to decode when a material first uses the image. With an
// EncodedImages as its user data, it counts what it keeps and refuses (tinygltf's load
// then fails with the reason) past `limit` (a hundred images of one 20 MB bufferView kept
// a copy each: 2 GB, then std::bad_alloc).
struct EncodedImages {
  uint64_t bytes = 0, limit = UINT64_MAX;
};
bool keep_image_encoded(tinygltf::Image* image, int image_index, std::string* err, std::string* warn, int req_width,
                        int req_height, const unsigned char* bytes, int size, void* user);

}  // namespace tessera
