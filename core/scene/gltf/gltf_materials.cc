#include "core/scene/gltf/gltf_materials.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace tessera {
namespace {

// A value of a material extension, when the file gives one.
const tinygltf::Value* ext_value(const tinygltf::ExtensionMap& exts, const char* ext, const char* key) {
  auto it = exts.find(ext);
  if (it == exts.end() || !it->second.IsObject() || !it->second.Has(key)) return nullptr;
  return &it->second.Get(key);
}
// A number of a material extension, `fallback` when absent; NaN or infinity refused.
double ext_number(const GltfContext& ctx, const tinygltf::ExtensionMap& exts, const char* ext, const char* key,
                  double fallback, const std::string& el) {
  const tinygltf::Value* v = ext_value(exts, ext, key);
  if (!v) return fallback;
  if (!v->IsNumber()) ctx.fail(el, std::string(ext) + "." + key + " is not a number");
  const double d = v->GetNumberAsDouble();
  if (!std::isfinite(d)) ctx.fail(el, std::string(ext) + "." + key + " is not finite");
  return d;
}
// A factor the specification bounds to [0, 1]: out of range refused.
double unit_factor(const GltfContext& ctx, double v, const std::string& el, const std::string& what) {
  if (!(v >= 0 && v <= 1)) ctx.fail(el, what + " " + std::to_string(v) + " is outside [0, 1]");
  return v;
}
Rgb color_factor(const GltfContext& ctx, const std::vector<double>& f, Rgb fallback, const std::string& el,
                 const std::string& what, double hi = 1) {
  if (f.empty()) return fallback;
  if (f.size() < 3) ctx.fail(el, what + " has " + std::to_string(f.size()) + " numbers, expected 3 or 4");
  for (size_t i = 0; i < 3; ++i)
    if (!(f[i] >= 0 && f[i] <= hi)) ctx.fail(el, what + " component " + std::to_string(f[i]) + " is out of range");
  return Rgb(float(f[0]), float(f[1]), float(f[2]));
}

// An extension's array of numbers (an element that is not a number reads as NaN, which
// color_factor refuses; not an array: none).
std::vector<double> numbers_of(const tinygltf::Value& v) {
  std::vector<double> f;
  if (v.IsArray())
    for (size_t i = 0; i < v.ArrayLen(); ++i)
      f.push_back(v.Get(int(i)).IsNumber() ? v.Get(int(i)).GetNumberAsDouble() : NAN);
  return f;
}

// KHR_materials_volume: thickness > 0 makes a solid; absorption from the attenuation colour
// reached after the attenuation distance: sigma = -ln(colour) / distance.
void read_volume(const GltfContext& ctx, const tinygltf::ExtensionMap& ex, const std::string& el, Material& m) {
  const double thickness = ext_number(ctx, ex, "KHR_materials_volume", "thicknessFactor", 0, el);
  if (!(thickness >= 0)) ctx.fail(el, "KHR_materials_volume.thicknessFactor is negative");
  m.thin = thickness == 0;
  const double distance = ext_number(ctx, ex, "KHR_materials_volume", "attenuationDistance", HUGE_VAL, el);
  if (!(distance > 0)) ctx.fail(el, "KHR_materials_volume.attenuationDistance must be positive");
  Rgb att(1.0f);
  if (const tinygltf::Value* v = ext_value(ex, "KHR_materials_volume", "attenuationColor"))
    att = color_factor(ctx, numbers_of(*v), Rgb(1.0f), el, "KHR_materials_volume.attenuationColor");
  if (!m.thin && std::isfinite(distance)) {
    auto sigma = [&](float c) { return float(-std::log(std::max(double(c), 1e-30)) / distance); };
    m.absorption = Rgb(sigma(att.r), sigma(att.g), sigma(att.b));
  }
}

// alphaMode, alphaCutoff and the base colour's alpha (Material::AlphaMode).
void read_alpha(const GltfContext& ctx, const tinygltf::Material& g, const std::string& el, Material& m) {
  const std::vector<double>& f = g.pbrMetallicRoughness.baseColorFactor;
  if (f.size() >= 4) m.opacity = float(unit_factor(ctx, f[3], el, "baseColorFactor alpha"));
  if (g.alphaMode == "OPAQUE" || g.alphaMode.empty()) {
    m.alpha_mode = Material::AlphaMode::kOpaque;
  } else if (g.alphaMode == "MASK") {
    m.alpha_mode = Material::AlphaMode::kMask;
    if (!(g.alphaCutoff >= 0 && std::isfinite(g.alphaCutoff)))
      ctx.fail(el, "alphaCutoff " + std::to_string(g.alphaCutoff) + " must be a finite number >= 0");
    m.alpha_cutoff = float(g.alphaCutoff);
  } else if (g.alphaMode == "BLEND") {
    m.alpha_mode = Material::AlphaMode::kBlend;
  } else {
    ctx.fail(el, "alphaMode '" + g.alphaMode + "' is not OPAQUE, MASK or BLEND");
  }
}

}  // namespace

// A texture reference inside a material extension (its index, texCoord, transform).
TextureRef GltfMaterials::ext_texture(const tinygltf::ExtensionMap& ex, const char* ext, const char* key, bool srgb,
                                      const std::string& el) {
  const tinygltf::Value* v = ext_value(ex, ext, key);
  if (!v) return TextureRef();
  if (!v->IsObject() || !v->Has("index") || !v->Get("index").IsInt())
    ctx_.fail(el, std::string(ext) + "." + key + " has no texture index");
  const int tex_coord = v->Has("texCoord") && v->Get("texCoord").IsInt() ? v->Get("texCoord").GetNumberAsInt() : 0;
  tinygltf::ExtensionMap exts;
  if (v->Has("extensions") && v->Get("extensions").IsObject())
    for (const std::string& k : v->Get("extensions").Keys()) exts[k] = v->Get("extensions").Get(k);
  return textures_.texture_ref(v->Get("index").GetNumberAsInt(), tex_coord, exts, srgb, el,
                               std::string(ext) + "." + key);
}

// KHR_materials_specular (Material::specular_ext).
void GltfMaterials::read_specular(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m) {
  if (!ex.count("KHR_materials_specular")) return;
  m.specular_ext = true;
  m.specular = float(unit_factor(ctx_, ext_number(ctx_, ex, "KHR_materials_specular", "specularFactor", 1, el), el,
                                 "KHR_materials_specular.specularFactor"));
  // Above 1 is allowed: it multiplies F0 (4% for ior 1.5), and F0 is clamped to 1.
  if (const tinygltf::Value* v = ext_value(ex, "KHR_materials_specular", "specularColorFactor"))
    m.specular_color =
        color_factor(ctx_, numbers_of(*v), Rgb(1.0f), el, "KHR_materials_specular.specularColorFactor", 1e4);
  m.specular_texture = ext_texture(ex, "KHR_materials_specular", "specularTexture", false, el);  // its alpha
  m.specular_color_texture = ext_texture(ex, "KHR_materials_specular", "specularColorTexture", true, el);
}

// KHR_materials_clearcoat (Material::clearcoat).
void GltfMaterials::read_clearcoat(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m) {
  if (!ex.count("KHR_materials_clearcoat")) return;
  const char* k = "KHR_materials_clearcoat";
  m.clearcoat = float(unit_factor(ctx_, ext_number(ctx_, ex, k, "clearcoatFactor", 0, el), el,
                                  "KHR_materials_clearcoat.clearcoatFactor"));
  m.clearcoat_roughness = float(unit_factor(ctx_, ext_number(ctx_, ex, k, "clearcoatRoughnessFactor", 0, el), el,
                                            "KHR_materials_clearcoat.clearcoatRoughnessFactor"));
  m.clearcoat_alpha = m.clearcoat_roughness * m.clearcoat_roughness;
  m.clearcoat_texture = ext_texture(ex, k, "clearcoatTexture", false, el);
  m.clearcoat_roughness_texture = ext_texture(ex, k, "clearcoatRoughnessTexture", false, el);
  m.clearcoat_normal_texture = ext_texture(ex, k, "clearcoatNormalTexture", false, el);
  if (const tinygltf::Value* v = ext_value(ex, k, "clearcoatNormalTexture"); v && v->Has("scale")) {
    const tinygltf::Value& s = v->Get("scale");
    m.clearcoat_normal_scale = s.IsNumber() ? float(s.GetNumberAsDouble()) : NAN;
    if (!std::isfinite(m.clearcoat_normal_scale))
      ctx_.fail(el, "KHR_materials_clearcoat.clearcoatNormalTexture.scale is not a finite number");
  }
}

// KHR_materials_sheen (Material::sheen_color).
void GltfMaterials::read_sheen(const tinygltf::ExtensionMap& ex, const std::string& el, Material& m) {
  const char* k = "KHR_materials_sheen";
  if (!ex.count(k)) return;
  if (const tinygltf::Value* v = ext_value(ex, k, "sheenColorFactor"))
    m.sheen_color = color_factor(ctx_, numbers_of(*v), Rgb(0.0f), el, "KHR_materials_sheen.sheenColorFactor");
  m.sheen_roughness = float(unit_factor(ctx_, ext_number(ctx_, ex, k, "sheenRoughnessFactor", 0, el), el,
                                        "KHR_materials_sheen.sheenRoughnessFactor"));
  m.sheen_color_texture = ext_texture(ex, k, "sheenColorTexture", true, el);
  m.sheen_roughness_texture = ext_texture(ex, k, "sheenRoughnessTexture", false, el);  // its alpha
}

uint32_t GltfMaterials::material(int index) {
  if (auto it = made_.find(index); it != made_.end()) return it->second;
  Material m;
  m.kind = Material::Kind::kPbr;
  const std::string el = "materials[" + std::to_string(index) + "]";
  // No material: the specification's default, white, metallic 1, roughness 1.
  m.reflectance = Rgb(1.0f);
  m.metallic = 1;
  m.roughness = 1;
  Rgb emissive(0.0f);
  double strength = 1;
  bool double_sided = false;
  TextureRef emissive_texture;
  if (index >= 0) {
    if (size_t(index) >= ctx_.model.materials.size()) ctx_.fail(el, "does not exist");
    const tinygltf::Material& g = ctx_.model.materials[size_t(index)];
    m.name = g.name;
    const auto& pbr = g.pbrMetallicRoughness;
    m.reflectance = color_factor(ctx_, pbr.baseColorFactor, Rgb(1.0f), el, "baseColorFactor");
    m.metallic = float(unit_factor(ctx_, pbr.metallicFactor, el, "metallicFactor"));
    m.roughness = float(unit_factor(ctx_, pbr.roughnessFactor, el, "roughnessFactor"));
    emissive = color_factor(ctx_, g.emissiveFactor, Rgb(0.0f), el, "emissiveFactor");
    double_sided = g.doubleSided;
    const auto& ex = g.extensions;
    strength = ext_number(ctx_, ex, "KHR_materials_emissive_strength", "emissiveStrength", 1, el);
    if (!(strength >= 0)) ctx_.fail(el, "KHR_materials_emissive_strength.emissiveStrength is negative");
    m.transmission =
        float(unit_factor(ctx_, ext_number(ctx_, ex, "KHR_materials_transmission", "transmissionFactor", 0, el), el,
                          "transmissionFactor"));
    // The extension allows any ior >= 1, and 0 (F0 = 1): specular-glossiness converters
    // write 0 or 1000 for "F0 from the specular colour" (KHR_materials_specular). A
    // refracting material's ior must be in [1, 10); an opaque one's only sets its Fresnel,
    // which past kMaxOpaqueIor (F0 0.9996) is taken as that, said.
    constexpr double kMaxOpaqueIor = 1e4;
    const double ior = ext_number(ctx_, ex, "KHR_materials_ior", "ior", 1.5, el);
    if (!(ior == 0 || (ior >= 1 && std::isfinite(ior))))
      ctx_.fail(el, "KHR_materials_ior ior " + std::to_string(ior) + " is neither 0 nor a finite number >= 1");
    if ((ior == 0 || ior >= 10) && m.transmission > 0)
      ctx_.fail(el, "KHR_materials_ior ior " + std::to_string(ior) +
                        " out of range [1, 10) for a material that transmits light (transmissionFactor " +
                        std::to_string(m.transmission) + ")");
    if (ior == 0 || ior > kMaxOpaqueIor)
      ctx_.warn_once(el + ": KHR_materials_ior ior " + std::to_string(ior) +
                     " is taken as 10000 (F0 0.9996; ior 0 means F0 1)");
    m.ior = float(ior == 0 ? kMaxOpaqueIor : std::min(ior, kMaxOpaqueIor));
    read_volume(ctx_, ex, el, m);
    read_specular(ex, el, m);
    read_clearcoat(ex, el, m);
    read_sheen(ex, el, m);
    m.texture = textures_.texture_ref(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord,
                                      pbr.baseColorTexture.extensions, true, el, "baseColorTexture");
    m.metal_rough_texture =
        textures_.texture_ref(pbr.metallicRoughnessTexture.index, pbr.metallicRoughnessTexture.texCoord,
                              pbr.metallicRoughnessTexture.extensions, false, el, "metallicRoughnessTexture");
    m.normal_texture = textures_.texture_ref(g.normalTexture.index, g.normalTexture.texCoord,
                                             g.normalTexture.extensions, false, el, "normalTexture");
    m.normal_scale = float(g.normalTexture.scale);
    if (!std::isfinite(m.normal_scale)) ctx_.fail(el, "normalTexture.scale is not finite");
    emissive_texture = textures_.texture_ref(g.emissiveTexture.index, g.emissiveTexture.texCoord,
                                             g.emissiveTexture.extensions, true, el, "emissiveTexture");
    m.transmission_texture = ext_texture(ex, "KHR_materials_transmission", "transmissionTexture", false, el);
    read_alpha(ctx_, g, el, m);
  }
  m.alpha = m.roughness * m.roughness;  // glTF's alpha = roughness^2
  // Emission adds to the reflected light (the specification's material model): the surface
  // keeps its BSDF. Scene::finalize decides whether it is bright enough to be sampled as a
  // light as well (Scene::kLampRadiance).
  m.radiance = emissive * float(strength);
  if (!m.radiance.is_black()) {
    m.two_sided_emission = double_sided;
    m.emissive_texture = emissive_texture;
  }
  const uint32_t id = ctx_.scene.add_material(std::move(m));
  made_[index] = id;
  return id;
}

}  // namespace tessera
