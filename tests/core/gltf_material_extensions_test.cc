// The glTF loader's material and texture extensions (issue 29): alphaMode and coverage,
// KHR_materials_specular, _clearcoat and _sheen, image formats (KTX2 and AVIF fallbacks, WebP
// decoded).
#include <webp/decode.h>
#include <webp/encode.h>

#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

// A 2x1 RGBA PNG, white, alpha 0 then 255, as a data URI.
std::string white_alpha_png_uri() {
  return "data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAIAAAABCAYAAAD0In+"
         "KAAAAEElEQVR4nGP4//8/AxD/BwAe6gb6OStlagAAAABJRU5ErkJggg==";
}

// Issue 29: alphaMode MASK and BLEND with their cutoff and the base colour's alpha (factor,
// texture alpha kept only where the image has translucent texels); bad values refused.
TEST_F(Gltf, AlphaModesAndCoverageAreRead) {
  Doc d;
  // A 2x1 RGBA PNG: white, alpha 0 then 255.
  d.j["images"] = {{{"uri", white_alpha_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["materials"][0] = {
      {"alphaMode", "MASK"},
      {"alphaCutoff", 0.25},
      {"pbrMetallicRoughness", {{"baseColorFactor", {1, 1, 1, 0.75}}, {"baseColorTexture", {{"index", 0}}}}}};
  Scene s = load(d);
  const Material& m = s.materials[s.meshes[0].material];
  EXPECT_EQ(m.alpha_mode, Material::AlphaMode::kMask);
  EXPECT_FLOAT_EQ(m.alpha_cutoff, 0.25f);
  EXPECT_FLOAT_EQ(m.opacity, 0.75f);
  const Texture& t = s.textures[size_t(m.texture.index)];
  ASSERT_EQ(t.size(), 2u);
  ASSERT_TRUE(t.has_alpha());
  EXPECT_FLOAT_EQ(t.texel_alpha(0), 0);
  EXPECT_FLOAT_EQ(t.texel_alpha(1), 1);
  d.j["materials"][0]["alphaMode"] = "BLEND";
  EXPECT_EQ(load(d).materials[0].alpha_mode, Material::AlphaMode::kBlend);
  d.j["materials"][0].erase("alphaMode");  // OPAQUE by default
  EXPECT_EQ(load(d).materials[0].alpha_mode, Material::AlphaMode::kOpaque);
  // An opaque image keeps no alpha.
  d.j["images"][0]["uri"] = red_blue_png_uri();
  s = load(d);
  EXPECT_FALSE(s.textures[0].has_alpha());
  EXPECT_FLOAT_EQ(s.textures[0].texel_alpha(0), 1);
  // Refused, naming the material.
  d.j["materials"][0]["alphaMode"] = "CUTOUT";
  expect_error(d, "materials[0]: alphaMode 'CUTOUT' is not OPAQUE, MASK or BLEND");
  d.j["materials"][0]["alphaMode"] = "MASK";
  d.j["materials"][0]["alphaCutoff"] = -1;
  expect_error(d, "alphaCutoff");
  d.j["materials"][0]["alphaCutoff"] = 0.5;
  d.j["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = {1, 1, 1, 1.5};
  expect_error(d, "baseColorFactor alpha 1.5");
}

// KHR_materials_transmission's texture: its R channel (linear) scales the factor, read
// without a warning (the red/blue image: R 1 on the left half, 0 on the right).
TEST_F(Gltf, TransmissionTextureScalesTheFactor) {
  Doc d;
  d.j["images"] = {{{"uri", red_blue_png_uri()}}};
  d.j["textures"] = {{{"source", 0}, {"sampler", 0}}};
  d.j["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33071}}};  // clamped
  d.j["materials"][0]["extensions"] = {
      {"KHR_materials_transmission", {{"transmissionFactor", 0.8}, {"transmissionTexture", {{"index", 0}}}}}};
  d.j["extensionsUsed"] = {"KHR_materials_transmission"};
  const Scene s = load(d);
  const Material& m = s.materials[s.meshes[0].material];
  ASSERT_TRUE(m.transmission_texture.active());
  EXPECT_NEAR(s.textured(m, {0.0f, 0.5f}).transmission, 0.8f, 1e-6);
  EXPECT_NEAR(s.textured(m, {1.0f, 0.5f}).transmission, 0.0f, 1e-6);
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("transmissionTexture"), std::string::npos) << w;
}

// Issue 29: KHR_materials_specular's factor, colour (above 1 allowed) and textures (the
// factor from specularTexture's alpha), and KHR_materials_clearcoat's, are read; out of
// range refused by name.
TEST_F(Gltf, SpecularAndClearcoatExtensionsAreRead) {
  Doc d;
  d.j["images"] = {{{"uri", white_alpha_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["materials"][0]["extensions"]["KHR_materials_specular"] = {
      {"specularFactor", 0.5}, {"specularColorFactor", {2, 1, 0.5}}, {"specularTexture", {{"index", 0}}}};
  d.j["extensionsUsed"] = {"KHR_materials_specular"};
  Scene s = load(d);
  const Material& m = s.materials[s.meshes[0].material];
  EXPECT_TRUE(m.specular_ext);
  EXPECT_FLOAT_EQ(m.specular, 0.5f);
  EXPECT_FLOAT_EQ(m.specular_color.r, 2);
  ASSERT_TRUE(m.specular_texture.active());
  // The texture's alpha (0 at u = 0.25, 1 at 0.75, clamped by the default repeat between)
  // scales the factor.
  EXPECT_NEAR(s.textured(m, {0.25f, 0.5f}).specular, 0, 1e-6);
  EXPECT_NEAR(s.textured(m, {0.75f, 0.5f}).specular, 0.5f, 1e-6);
  d.j["materials"][0]["extensions"]["KHR_materials_specular"]["specularFactor"] = 1.5;
  expect_error(d, "KHR_materials_specular.specularFactor 1.500000 is outside [0, 1]");
  // KHR_materials_clearcoat likewise, its normal texture and scale read without a warning.
  d.j["materials"][0]["extensions"].erase("KHR_materials_specular");
  d.j["materials"][0]["extensions"]["KHR_materials_clearcoat"] = {
      {"clearcoatFactor", 0.75},
      {"clearcoatRoughnessFactor", 0.5},
      {"clearcoatNormalTexture", {{"index", 0}, {"scale", 0.5}}}};
  d.j["extensionsUsed"] = {"KHR_materials_clearcoat"};
  s = load(d);
  const Material& c = s.materials[s.meshes[0].material];
  EXPECT_FLOAT_EQ(c.clearcoat, 0.75f);
  EXPECT_FLOAT_EQ(c.clearcoat_alpha, 0.25f);
  EXPECT_TRUE(c.clearcoat_normal_texture.active());
  EXPECT_FLOAT_EQ(c.clearcoat_normal_scale, 0.5f);
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("clearcoatNormalTexture"), std::string::npos) << w;
  d.j["materials"][0]["extensions"]["KHR_materials_clearcoat"]["clearcoatNormalTexture"]["scale"] = "big";
  expect_error(d, "clearcoatNormalTexture.scale is not a finite number");
  d.j["materials"][0]["extensions"]["KHR_materials_clearcoat"]["clearcoatFactor"] = -1;
  expect_error(d, "KHR_materials_clearcoat.clearcoatFactor");
}

// Found by audit: a coat-only normal map ignored the file's TANGENTs (read only for the
// base's normal map: the coat tilted the wrong way), and an extension's texture reading
// TEXCOORD_1 on a mesh without it was not said (the base's four were).
TEST_F(Gltf, ACoatsNormalMapReadsTheTangentsAndEveryTexturesCoordinateSetIsChecked) {
  Doc d;
  d.blob.resize(88);
  put<float>(d.blob, {1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1});  // tangents, 48 bytes at 88
  d.j["accessors"].push_back({{"bufferView", 4}, {"componentType", 5126}, {"count", 3}, {"type", "VEC4"}});
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 88}, {"byteLength", 48}});
  d.j["buffers"][0]["byteLength"] = 136;
  d.j["meshes"][0]["primitives"][0]["attributes"]["TANGENT"] = 4;
  d.j["images"] = {{{"uri", white_alpha_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["materials"][0]["extensions"]["KHR_materials_clearcoat"] = {
      {"clearcoatFactor", 1},
      {"clearcoatNormalTexture", {{"index", 0}}},
      {"clearcoatTexture", {{"index", 0}, {"texCoord", 1}}}};
  d.j["extensionsUsed"] = {"KHR_materials_clearcoat"};
  const Scene s = load(d);
  EXPECT_EQ(s.meshes[0].tangents.size(), 3u);
  bool said = false;
  for (const std::string& w : s.warnings) said |= w.find("reads TEXCOORD_1, which it lacks") != std::string::npos;
  EXPECT_TRUE(said);
}

// Issue 29: KHR_materials_sheen's colour (x its sRGB texture) and roughness (x its
// texture's alpha) are read without a warning; out of range refused by name.
TEST_F(Gltf, SheenExtensionIsRead) {
  Doc d;
  d.j["images"] = {{{"uri", white_alpha_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["materials"][0]["extensions"]["KHR_materials_sheen"] = {{"sheenColorFactor", {1, 0.5, 0.25}},
                                                              {"sheenRoughnessFactor", 0.6},
                                                              {"sheenColorTexture", {{"index", 0}}},
                                                              {"sheenRoughnessTexture", {{"index", 0}}}};
  d.j["extensionsUsed"] = {"KHR_materials_sheen"};
  const Scene s = load(d);
  const Material& m = s.materials[s.meshes[0].material];
  EXPECT_FLOAT_EQ(m.sheen_color.g, 0.5f);
  EXPECT_FLOAT_EQ(m.sheen_roughness, 0.6f);
  EXPECT_FALSE(m.is_delta());
  EXPECT_NEAR(s.textured(m, {0.75f, 0.5f}).sheen_color.b, 0.25f, 1e-6);  // white texel
  EXPECT_NEAR(s.textured(m, {0.25f, 0.5f}).sheen_roughness, 0, 1e-6);    // alpha 0
  EXPECT_NEAR(s.textured(m, {0.75f, 0.5f}).sheen_roughness, 0.6f, 1e-6);
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("sheen"), std::string::npos) << w;
  d.j["materials"][0]["extensions"]["KHR_materials_sheen"]["sheenColorFactor"] = {1, 2, 0};
  expect_error(d, "KHR_materials_sheen.sheenColorFactor component 2");
}

// Issue 29: KTX2 textures (KHR_texture_basisu) have no decoder here: a texture's PNG or
// JPEG fallback is used with a warning; one without a fallback, or a file that requires
// the extension, is refused saying so.
TEST_F(Gltf, Ktx2TexturesUseTheirFallbackOrAreRefusedClearly) {
  Doc d;
  d.j["images"] = {{{"uri", red_blue_png_uri()}}, {{"uri", "data:image/ktx2;base64,q0tUWCAyMLsNChoK"}}};
  d.j["textures"] = {{{"source", 0}, {"extensions", {{"KHR_texture_basisu", {{"source", 1}}}}}}};
  d.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
  d.j["extensionsUsed"] = {"KHR_texture_basisu"};
  const Scene s = load(d);
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(s.textures[0].width, 2);  // the PNG
  bool warned = false;
  for (const std::string& w : s.warnings) warned |= w.find("PNG or JPEG fallback is used") != std::string::npos;
  EXPECT_TRUE(warned);
  d.j["textures"][0].erase("source");
  expect_error(d, "textures[0]: has only a KTX2 / Basis Universal image (KHR_texture_basisu)");
  // AVIF likewise.
  d.j["textures"][0]["extensions"] = {{"EXT_texture_avif", {{"source", 1}}}};
  expect_error(d, "textures[0]: has only a AVIF image (EXT_texture_avif)");
  d.j["textures"][0]["extensions"] = {{"KHR_texture_basisu", {{"source", 1}}}};
  d.j["extensionsRequired"] = {"KHR_texture_basisu"};
  expect_error(d, "KTX2 / Basis Universal textures cannot be decoded here");
}

// Issue 29: EXT_texture_webp's image is decoded (libwebp) and preferred to the fallback;
// a damaged one is refused naming it.
TEST_F(Gltf, WebPTexturesAreDecoded) {
  const uint8_t rgba[8] = {255, 0, 0, 255, 0, 0, 255, 128};  // red, then half-transparent blue
  uint8_t* out = nullptr;
  const size_t n = WebPEncodeLosslessRGBA(rgba, 2, 1, 8, &out);
  ASSERT_GT(n, 0u);
  const std::string webp(reinterpret_cast<const char*>(out), n);
  WebPFree(out);
  Doc d;
  d.j["images"] = {{{"uri", red_blue_png_uri()}}, {{"uri", "data:image/webp;base64," + base64(webp)}}};
  d.j["textures"] = {{{"source", 0}, {"extensions", {{"EXT_texture_webp", {{"source", 1}}}}}}};
  d.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
  d.j["extensionsUsed"] = {"EXT_texture_webp"};
  const Scene s = load(d);
  ASSERT_EQ(s.textures.size(), 1u);
  const Texture& t = s.textures[0];
  ASSERT_EQ(t.size(), 2u);
  EXPECT_FLOAT_EQ(t.texel(0).r, 1);  // lossless: exact
  EXPECT_FLOAT_EQ(t.texel(1).b, 1);
  ASSERT_TRUE(t.has_alpha());
  EXPECT_NEAR(t.texel_alpha(1), 128 / 255.0, 1e-6);
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("EXT_texture_webp"), std::string::npos) << w;
  Doc x;  // KHR_xmp_json_ld is metadata: accepted without a warning
  x.j["extensionsUsed"] = {"KHR_xmp_json_ld"};
  for (const std::string& w : load(x).warnings) EXPECT_EQ(w.find("KHR_xmp_json_ld"), std::string::npos) << w;
  d.j["images"][1]["uri"] = "data:image/webp;base64," + base64(webp.substr(0, webp.size() / 2));
  expect_error(d, "images[1]: the WebP image is damaged or cut short and cannot be decoded");
}

}  // namespace
}  // namespace tessera
