#include "core/scene/gltf/gltf_textures.h"

#include <stb/stb_image.h>
#include <webp/decode.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <utility>

#include "core/math/float_math.h"
#include "core/scene/gltf/gltf_extensions.h"
#include "core/util/cancel.h"

namespace tessera {
namespace {

constexpr uint64_t kMaxImagePixels = uint64_t(1) << 26;  // 64 M texels
constexpr int kEncoded = -1;                             // tinygltf::Image::component of bytes not yet decoded
constexpr int kTaken = -2;                               // ... of pixels GltfTextures holds (image_pixels)

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : fm::pow((c + 0.055f) / 1.055f, 2.4f); }

// srgb_to_linear(byte / 255) for every byte: sRGB colour textures decoded by a lookup.
const std::array<float, 256>& srgb_bytes() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int c = 0; c < 256; ++c) t[size_t(c)] = srgb_to_linear(c / 255.0f);
    return t;
  }();
  return table;
}

// An image's size from its header, refused over kMaxImagePixels before anything is allocated.
void check_size(const GltfContext& ctx, int w, int h, const std::string& el) {
  if (w <= 0 || h <= 0 || uint64_t(w) * uint64_t(h) > kMaxImagePixels)
    ctx.fail(el, std::to_string(w) + "x" + std::to_string(h) + " is over the 64 M texel limit");
}

// A decoder's RGBA 8-bit pixels kept as the image's, decoded.
void keep_rgba(tinygltf::Image& img, const unsigned char* rgba, int w, int h) {
  img.width = w;
  img.height = h;
  img.component = 4;
  img.bits = 8;
  img.image.assign(rgba, rgba + size_t(w) * size_t(h) * 4);
}

}  // namespace

bool keep_image_encoded(tinygltf::Image* image, const int index, std::string* err, std::string*, int, int,
                        const unsigned char* bytes, int size, void* user) {
  if (auto* kept = static_cast<EncodedImages*>(user)) {
    kept->bytes += uint64_t(std::max(size, 0));
    if (kept->bytes > kept->limit) {
      if (err)
        *err += "images[" + std::to_string(index) + "]: the images' encoded bytes pass " +
                std::to_string(kept->limit >> 20) + " MiB, the limit of a glTF load (each image holds its own copy)";
      return false;
    }
  }
  image->image.assign(bytes, bytes + size);
  image->width = image->height = 0;
  image->component = kEncoded;
  return true;
}

TextureRef GltfTextures::texture_ref(int index, int tex_coord, const tinygltf::ExtensionMap& exts, bool srgb,
                                     const std::string& el, const std::string& what) {
  TextureRef r;
  if (index < 0) return r;
  r.index = load_texture(index, el + " " + what, srgb);
  if (auto it = exts.find("KHR_texture_transform"); it != exts.end() && it->second.IsObject()) {
    const tinygltf::Value& t = it->second;
    auto pair = [&](const char* key, double x, double y) -> std::pair<double, double> {
      if (!t.Has(key)) return {x, y};
      const tinygltf::Value& v = t.Get(key);
      if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber())
        ctx_.fail(el, what + " KHR_texture_transform." + key + " is not two numbers");
      const double a = v.Get(0).GetNumberAsDouble(), b = v.Get(1).GetNumberAsDouble();
      if (!std::isfinite(a) || !std::isfinite(b))
        ctx_.fail(el, what + " KHR_texture_transform." + key + " is not finite");
      return {a, b};
    };
    const auto [ox, oy] = pair("offset", 0, 0);
    const auto [sx, sy] = pair("scale", 1, 1);
    double rot = 0;
    if (t.Has("rotation")) {
      if (!t.Get("rotation").IsNumber() || !std::isfinite(t.Get("rotation").GetNumberAsDouble()))
        ctx_.fail(el, what + " KHR_texture_transform.rotation is not a finite number");
      rot = t.Get("rotation").GetNumberAsDouble();
    }
    // uv' = T R S uv, R = [cos sin; -sin cos] (the extension's matrix).
    const double c = std::cos(rot), sn = std::sin(rot);
    const double m[6] = {c * sx, sn * sy, ox, -sn * sx, c * sy, oy};
    for (int i = 0; i < 6; ++i) r.xform[i] = float(m[i]);
    if (t.Has("texCoord") && t.Get("texCoord").IsInt()) tex_coord = t.Get("texCoord").GetNumberAsInt();
  }
  if (tex_coord == 1)
    r.set = 1;
  else if (tex_coord > 1)
    ctx_.warn_once(el + ": " + what + " uses TEXCOORD_" + std::to_string(tex_coord) +
                   " (only TEXCOORD_0 and TEXCOORD_1 are read); TEXCOORD_0 is used");
  return r;
}

// Colour textures (base colour, emission) are sRGB-encoded, data (metallic-roughness,
// normals) linear: a texture used both ways is decoded twice.
int GltfTextures::load_texture(int index, const std::string& el, bool srgb) {
  const tinygltf::Model& model = ctx_.model;
  if (index < 0 || size_t(index) >= model.textures.size())
    ctx_.fail(el, "texture " + std::to_string(index) + " does not exist");
  const int key = 2 * index + (srgb ? 1 : 0);
  if (auto it = loaded_.find(key); it != loaded_.end()) return it->second;
  throw_if_cancelled();
  const tinygltf::Texture& t = model.textures[size_t(index)];
  const std::string tel = "textures[" + std::to_string(index) + "]";
  for (const auto& [ext, format] : kGltfImageFormatExtensions)
    if (t.source < 0 && t.extensions.count(ext))
      ctx_.fail(tel, std::string("has only a ") + format + " image (" + ext +
                         "), which cannot be decoded here, and no PNG or JPEG fallback `source`");
  int source = t.source;
  // EXT_texture_webp: its image is preferred (libwebp decodes it); `source` is the fallback.
  if (auto it = t.extensions.find("EXT_texture_webp");
      it != t.extensions.end() && it->second.IsObject() && it->second.Has("source") && it->second.Get("source").IsInt())
    source = it->second.Get("source").GetNumberAsInt();
  if (source < 0 || size_t(source) >= model.images.size())
    ctx_.fail(tel, "image " + std::to_string(source) + " does not exist");
  Texture::Wrap wrap_s = Texture::Wrap::kRepeat, wrap_t = Texture::Wrap::kRepeat;
  bool nearest = false;
  if (t.sampler >= 0) {
    if (size_t(t.sampler) >= model.samplers.size())
      ctx_.fail(tel, "sampler " + std::to_string(t.sampler) + " does not exist");
    auto wrap = [&](int mode) {
      switch (mode) {
        case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE:
          return Texture::Wrap::kClamp;
        case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT:
          return Texture::Wrap::kMirror;
        default:
          return Texture::Wrap::kRepeat;
      }
    };
    wrap_s = wrap(model.samplers[size_t(t.sampler)].wrapS);
    wrap_t = wrap(model.samplers[size_t(t.sampler)].wrapT);
    nearest = model.samplers[size_t(t.sampler)].magFilter == TINYGLTF_TEXTURE_FILTER_NEAREST;
  }
  const auto same = std::make_tuple(source, srgb, int(wrap_s), int(wrap_t), nearest);
  if (auto it = same_.find(same); it != same_.end()) return loaded_[key] = it->second;
  const Pixels& pixels = image_pixels(source, tel);
  Texture tex;
  tex.width = pixels.width;
  tex.height = pixels.height;
  // The bytes themselves, shared, decoded as they are looked up (Texture::rgba8); alpha
  // (always linear) counts where some texel is not opaque: the base colour's coverage for
  // alphaMode MASK and BLEND (Scene::opacity_at), KHR_materials_specular's specularTexture.
  tex.rgba8 = pixels.rgba;
  tex.rgba8_translucent = pixels.translucent;
  tex.decode = srgb ? &srgb_bytes() : &byte_fractions();
  tex.wrap_s = wrap_s;
  tex.wrap_t = wrap_t;
  tex.nearest = nearest;
  ctx_.scene.textures.push_back(std::move(tex));
  return loaded_[key] = same_[same] = int(ctx_.scene.textures.size() - 1);
}

// images[index]'s pixels, decoded once and then held here (not by the model): every texture
// made of it shares them, its colour spaces and samplers alike.
const GltfTextures::Pixels& GltfTextures::image_pixels(int index, const std::string& el) {
  if (auto it = pixels_.find(index); it != pixels_.end()) return it->second;
  tinygltf::Image& img = decode_image(index);
  const uint64_t texels = uint64_t(img.width) * uint64_t(img.height);
  if (texels_ + texels > ctx_.max_scene_texels)
    ctx_.fail(el, "the scene's textures would hold " + std::to_string(texels_ + texels) +
                      " texels, over the limit of " + std::to_string(ctx_.max_scene_texels) +
                      " (each image counted once)");
  texels_ += texels;
  ctx_.charge(el, "textures", texels * 4);  // (RGBA bytes, shared by the textures made of it)
  Pixels p;
  p.width = img.width;
  p.height = img.height;
  img.image.resize(size_t(texels) * 4);
  for (size_t i = 0; i < size_t(texels) && !p.translucent; ++i) p.translucent = img.image[4 * i + 3] != 255;
  p.rgba = std::make_shared<const std::vector<uint8_t>>(std::move(img.image));
  img.image = {};
  img.component = kTaken;
  return pixels_[index] = std::move(p);
}

// A WebP image (EXT_texture_webp) through libwebp, to RGBA 8-bit, with the same limit.
tinygltf::Image& GltfTextures::decode_webp(tinygltf::Image& img, const std::string& el) {
  int w = 0, h = 0;
  if (!WebPGetInfo(img.image.data(), img.image.size(), &w, &h))
    ctx_.fail(el, "the WebP image is damaged or cut short and cannot be decoded");
  check_size(ctx_, w, h, el);
  uint8_t* data = WebPDecodeRGBA(img.image.data(), img.image.size(), &w, &h);
  if (!data) ctx_.fail(el, "the WebP image is damaged or cut short and cannot be decoded");
  keep_rgba(img, data, w, h);
  WebPFree(data);
  return img;
}

// Decodes images[index] (PNG or JPEG, RGBA 8-bit), refusing absurd sizes before
// allocating; once, whatever number of textures use it.
tinygltf::Image& GltfTextures::decode_image(int index) {
  tinygltf::Image& img = ctx_.model.images[size_t(index)];
  // Named by its file where it has one: the user looks for the file.
  const bool file = !img.uri.empty() && img.uri.rfind("data:", 0) != 0;
  const std::string el = "images[" + std::to_string(index) + "]" + (file ? " ('" + img.uri + "')" : "");
  if (img.component != kEncoded) {
    if (img.width <= 0 || img.height <= 0 || img.image.size() < size_t(img.width) * size_t(img.height) * 4)
      ctx_.fail(el, "has no pixel data");
    return img;
  }
  if (img.image.empty()) ctx_.fail(el, file ? "the file is missing or empty" : "has no data");
  if (img.image.size() >= 12 && std::memcmp(img.image.data(), "RIFF", 4) == 0 &&
      std::memcmp(img.image.data() + 8, "WEBP", 4) == 0)
    return decode_webp(img, el);
  int w = 0, h = 0, comp = 0;
  const int size = int(std::min<size_t>(img.image.size(), size_t(INT32_MAX)));
  // PNG and JPEG only, by their signatures (glTF's formats; WebP above): stb decodes TGA,
  // BMP, GIF, PSD, PIC, PNM and HDR too, and its TGA reader rendered a truncated file's
  // missing texels from uninitialised memory, different each run.
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'}, kJpeg[3] = {0xFF, 0xD8, 0xFF};
  const bool png = img.image.size() >= 8 && std::memcmp(img.image.data(), kPng, 8) == 0;
  const bool jpeg = img.image.size() >= 3 && std::memcmp(img.image.data(), kJpeg, 3) == 0;
  if (!(png || jpeg) || !stbi_info_from_memory(img.image.data(), size, &w, &h, &comp)) {
    // A KTX2 file named directly (no KHR_texture_basisu, so no fallback) is common enough
    // to name: the user needs a PNG or JPEG version of it.
    static const unsigned char kKtx2[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
    if (img.image.size() >= 12 && std::memcmp(img.image.data(), kKtx2, 12) == 0)
      ctx_.fail(el,
                "is a KTX2 image, which Tessera cannot decode (no KTX2 library here): give the texture a PNG or "
                "JPEG source (KHR_texture_basisu's fallback)");
    ctx_.fail(el, png || jpeg ? "not a readable PNG or JPEG image (its header does not read)"
                              : "not a PNG, JPEG or WebP image (glTF's image formats)");
  }
  check_size(ctx_, w, h, el);
  unsigned char* data = stbi_load_from_memory(img.image.data(), size, &w, &h, &comp, 4);
  if (!data) {  // stb's reasons are short codes ("outofdata", "bad zlib header", ...)
    const std::string why = stbi_failure_reason() ? stbi_failure_reason() : "unknown";
    ctx_.fail(el, why == "outofdata" ? "the image is cut short (a truncated PNG or JPEG)"
                                     : "the image is damaged and cannot be decoded (" + why + ")");
  }
  keep_rgba(img, data, w, h);
  stbi_image_free(data);
  return img;
}

}  // namespace tessera
