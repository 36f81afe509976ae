// The renderer's scene model: what every loader (COLLADA, glTF) produces and every other
// part of the core consumes. Plain data in world space, +Y up (an instanced mesh in its own
// object space, placed by Scene::instances); no file-format concepts.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/math/vec.h"
#include "core/scene/instance.h"

namespace tessera {

// A texture as a material uses it: which one (Scene::textures), and KHR_texture_transform's
// affine map of the coordinates, uv' = [m0 m1 m2; m3 m4 m5] (u, v, 1).
struct TextureRef {
  int32_t index = -1;
  uint8_t set = 0;  // the texture coordinates it reads: Mesh::uvs (0) or Mesh::uvs1 (1)
  float xform[6] = {1, 0, 0, 0, 1, 0};
  bool active() const { return index >= 0; }
  Vec2 map(Vec2 uv) const {
    return {xform[0] * uv.x + xform[1] * uv.y + xform[2], xform[3] * uv.x + xform[4] * uv.y + xform[5]};
  }
};

// Material parameters. One struct with a kind tag rather than a class hierarchy: the
// integrator switches on the kind, which keeps the hot loop free of virtual calls.
//
// kDiffuse..kMicrofacet and kEmission are CS184's materials with their CS184 meanings.
// kPbr is glTF's metallic-roughness model (core/bsdf/bsdf.cc, docs/gltf.md), used for glTF
// materials only: a CS184 scene never meets it.
struct Material {
  enum class Kind : uint8_t { kDiffuse, kMirror, kGlass, kRefraction, kMicrofacet, kEmission, kPbr };
  Kind kind = Kind::kDiffuse;
  std::string name;
  Rgb reflectance{0.5f};    // diffuse albedo, mirror and glass reflectance; kPbr base colour
  Rgb transmittance{1.0f};  // glass and refraction
  float ior = 1.5f;         // glass, refraction, kPbr: interior / exterior
  float alpha = 0.25f;      // microfacet Beckmann roughness; kPbr GGX alpha (roughness^2)
  Rgb eta{0.2f}, k{3.0f};   // microfacet conductor complex index, per channel
  // Emitted radiance: kEmission's (an emitter that does not reflect), or a kPbr surface's
  // own (glTF's emissive), which adds to its reflection. One-sided emission leaves the
  // side the geometric normal faces.
  Rgb radiance{0.0f};
  bool two_sided_emission = true;
  TextureRef texture;  // multiplies `reflectance` (sRGB-decoded); kPbr: the base colour texture

  // kPbr only.
  float metallic = 0;      // 0 dielectric .. 1 metal (continuous)
  float roughness = 1;     // perceptual; alpha = roughness^2
  float transmission = 0;  // KHR_materials_transmission: the dielectric part's share that transmits
  // Its R channel scales `transmission` (linear).
  TextureRef transmission_texture;
  // KHR_materials_volume: a solid (refracting, Beer-Lambert absorption `absorption` per unit
  // length inside) rather than thin-walled (transmission passes without bending).
  bool thin = true;
  Rgb absorption{0.0f};
  TextureRef metal_rough_texture;  // linear: G scales roughness, B metallic
  TextureRef normal_texture;       // tangent-space normal map (linear)
  float normal_scale = 1;
  TextureRef emissive_texture;  // multiplies `radiance` (sRGB-decoded)
  // KHR_materials_specular: the dielectric's Fresnel reflectance F0 tinted by
  // `specular_color` (x its texture, sRGB), the whole layer scaled by `specular` (x its
  // texture's alpha); the diffuse and transmission under it keep 1 - specular x max(F).
  // Off (`specular_ext` false) the BSDF takes its exact-Fresnel path unchanged.
  bool specular_ext = false;
  float specular = 1;
  Rgb specular_color{1.0f};
  TextureRef specular_texture, specular_color_texture;
  // KHR_materials_clearcoat: a smooth or rough (GGX, alpha = clearcoat_roughness^2)
  // dielectric coat of ior 1.5 over the whole material, weighted by `clearcoat` (x its
  // texture's R; roughness x its texture's G). 0: no coat, the plain path.
  float clearcoat = 0, clearcoat_roughness = 0, clearcoat_alpha = 0;
  TextureRef clearcoat_texture, clearcoat_roughness_texture;
  // clearcoatNormalTexture (x its scale): the coat's own normal, which the integrator puts
  // in `coat_normal`, in the base's shading frame (z: the base's normal; the coat follows
  // it where there is no map).
  TextureRef clearcoat_normal_texture;
  float clearcoat_normal_scale = 1;
  Vec3 coat_normal{0, 0, 1};
  // KHR_materials_sheen: a microfibre layer of colour `sheen_color` (x its texture, sRGB)
  // and roughness `sheen_roughness` (x its texture's alpha) over the base, under the coat
  // (core/bsdf/sheen.h). Black: no sheen, the plain path.
  Rgb sheen_color{0.0f};
  float sheen_roughness = 0;
  TextureRef sheen_color_texture, sheen_roughness_texture;
  // glTF alphaMode: how much of the surface is there, from the coverage `opacity` x the base
  // colour texture's alpha x COLOR_0's alpha (Scene::opacity_at). OPAQUE ignores it; MASK
  // keeps the surface where it reaches `alpha_cutoff`, BLEND where a uniform number per ray
  // and triangle is below it (stochastic transparency: unbiased, no sorting). Decided in the
  // intersection filter (core/accel), installed only on meshes with such a material.
  enum class AlphaMode : uint8_t { kOpaque, kMask, kBlend };
  AlphaMode alpha_mode = AlphaMode::kOpaque;
  float opacity = 1;  // baseColorFactor's alpha
  float alpha_cutoff = 0.5f;

  // Below this alpha a kPbr surface's specular lobes are perfectly smooth (delta).
  static constexpr float kSmoothAlpha = 1e-3f;
  bool is_delta() const {
    if (kind == Kind::kPbr)
      return alpha < kSmoothAlpha && metallic + (1 - metallic) * transmission >= 1 &&
             (clearcoat <= 0 || clearcoat_alpha < kSmoothAlpha) && sheen_color.is_black();
    return kind == Kind::kMirror || kind == Kind::kGlass || kind == Kind::kRefraction;
  }
  // True if the surface glows (camera and BSDF paths that reach it add `radiance`).
  bool emits() const { return !radiance.is_black(); }
  // True if no BSDF lobe exists: paths end here.
  bool is_black() const { return kind == Kind::kEmission; }
  // Keeps the outward normal (a path can be inside it) rather than shading the side the
  // ray came from.
  bool is_dielectric() const {
    return kind == Kind::kGlass || kind == Kind::kRefraction || (kind == Kind::kPbr && transmission > 0);
  }
  bool has_textures() const {
    return texture.active() || metal_rough_texture.active() || normal_texture.active() || emissive_texture.active() ||
           transmission_texture.active() || specular_texture.active() || specular_color_texture.active() ||
           clearcoat_texture.active() || clearcoat_roughness_texture.active() || clearcoat_normal_texture.active() ||
           sheen_color_texture.active() || sheen_roughness_texture.active();
  }
};

// glTF TANGENT: a vertex's tangent (unit, along increasing u of the normal map's
// coordinates) and the sign that makes the bitangent cross(N, T) x sign.
struct Tangent {
  Vec3 t;
  float sign = 1;
};

struct Mesh {
  std::string name;
  std::vector<Vec3> positions;
  std::vector<uint32_t> indices;   // 3 per triangle
  std::vector<Vec3> normals;       // per vertex: from the file, or area weighted (compute_normals)
  std::vector<Vec2> uvs;           // per vertex texture coordinates, or empty
  std::vector<Vec2> uvs1;          // a second set (glTF TEXCOORD_1), or empty
  std::vector<Rgb> colors;         // per vertex colour (glTF COLOR_0, linear), multiplying the base colour; or empty
  std::vector<float> color_alpha;  // COLOR_0's alpha where the file gives one below 1, or empty
  // The file's TANGENTs, read only for a material with a normal map (else empty, and the
  // normal map's frame is the triangle's own: apply_normal_map).
  std::vector<Tangent> tangents;
  bool file_normals = false;  // `normals` came from the file: keep them
  // Flat shaded: its triangles' own normals shade it (`normals` all zero: the surface point
  // takes the geometric normal). glTF's rule for a primitive without NORMAL (spec 3.7.2.1);
  // a COLLADA mesh without normals gets vertex normals instead (compute_normals).
  bool flat = false;
  // Placed only by Scene::instances: its positions and normals are in its object space,
  // and it is in the world nowhere else.
  bool instanced = false;
  uint32_t material = 0;
  int32_t light = -1;  // index into Scene::lights when the mesh emits

  size_t triangle_count() const { return indices.size() / 3; }
  // The coordinates of set `set` (`uvs` where the mesh has no second set).
  const std::vector<Vec2>& uv_set(int set) const { return set == 1 && !uvs1.empty() ? uvs1 : uvs; }
  // Texture coordinates at barycentrics (b1, b2) of triangle `tri`; uvs must not be empty.
  Vec2 uv_at(size_t tri, float b1, float b2, int set = 0) const {
    const float b0 = 1 - b1 - b2;
    const std::vector<Vec2>& uv = uv_set(set);
    const Vec2 a = uv[indices[3 * tri]], b = uv[indices[3 * tri + 1]], c = uv[indices[3 * tri + 2]];
    return {a.x * b0 + b.x * b1 + c.x * b2, a.y * b0 + b.y * b1 + c.y * b2};
  }
  void compute_normals();
};

struct Sphere {
  std::string name;
  Vec3 center;
  float radius = 1;
  uint32_t material = 0;
  int32_t light = -1;
};

class EnvironmentMap;  // core/light/environment.h

struct Light {
  enum class Kind : uint8_t { kRect, kMesh, kSphere, kPoint, kSpot, kDirectional, kAmbient, kEnvironment };
  Kind kind = Kind::kPoint;
  std::string name;
  Rgb color{1.0f};  // radiance (rect, mesh, sphere, ambient, environment), intensity (point),
                    // irradiance at normal incidence (directional)
  // Rect: centre, full edge vectors, facing normal (emits toward it), area.
  Vec3 position, edge_x, edge_y, normal;
  float area = 0;
  // Point: attenuation 1 / (c + l d + q d^2).
  float att_constant = 1, att_linear = 0, att_quadratic = 0;
  Vec3 direction;                      // directional: unit vector toward the light; spot: the way it shines
  float cos_inner = 1, cos_outer = 0;  // spot: full intensity inside the inner cone, none outside
  uint32_t shape = 0;                  // kMesh: mesh index; kSphere: sphere index; kRect: its mesh
  bool two_sided = false;
  // kEnvironment: an image (radiance = color x map(direction)); null for a uniform one.
  std::shared_ptr<const EnvironmentMap> map;

  bool is_delta() const { return kind == Kind::kPoint || kind == Kind::kSpot || kind == Kind::kDirectional; }
  bool is_infinite() const {
    return kind == Kind::kDirectional || kind == Kind::kAmbient || kind == Kind::kEnvironment;
  }
};

// An RGB texture in linear values, bilinearly filtered, with glTF's wrap modes. Its texels
// are floats (`texels`: HDR images, tests) or an 8-bit image's bytes (`rgba8`: glTF's PNG,
// JPEG and WebP images), decoded as they are looked up: 4 bytes a texel instead of 16, the
// same values bit for bit as decoding them all first.
struct Texture {
  enum class Wrap : uint8_t { kRepeat, kClamp, kMirror };
  int width = 0, height = 0;
  std::vector<Rgb> texels;   // row-major, row 0 at v = 0 (empty where rgba8 holds them)
  std::vector<float> alpha;  // the image's alpha, as texels, where some texel is not opaque; else empty
  // An 8-bit image: RGBA, 4 bytes a texel in `texels`' order, shared by every texture made
  // of the image (its colour spaces and samplers); `decode` (a table that lives as long as
  // the process) maps a colour byte to its linear value (sRGB or linear data), alpha is
  // always byte_fractions(). Null: `texels`.
  std::shared_ptr<const std::vector<uint8_t>> rgba8;
  const std::array<float, 256>* decode = nullptr;
  bool rgba8_translucent = false;  // some texel of rgba8 is not opaque
  Wrap wrap_s = Wrap::kRepeat, wrap_t = Wrap::kRepeat;
  // glTF magFilter NEAREST: the texel the point falls in, not a bilinear blend (pixel art
  // stays sharp, as Blender's importer shows it with Closest). Minification needs no
  // mipmaps here: pixels are supersampled.
  bool nearest = false;
  Rgb sample(Vec2 uv) const;
  float sample_alpha(Vec2 uv) const;  // 1 without an alpha channel
  Rgb mean() const;                   // over all texels
  bool has_alpha() const { return rgba8 ? rgba8_translucent : !alpha.empty(); }
  size_t size() const { return size_t(width) * size_t(height); }
  Rgb texel(size_t i) const {  // row-major index, decoded
    if (!rgba8) return texels[i];
    const uint8_t* p = rgba8->data() + 4 * i;
    return Rgb((*decode)[p[0]], (*decode)[p[1]], (*decode)[p[2]]);
  }
  float texel_alpha(size_t i) const;  // 1 without an alpha channel
};

// byte / 255.0f for every byte: 8-bit data decoded by a lookup instead of a division.
const std::array<float, 256>& byte_fractions();

struct SceneAnimation;  // core/scene/animation.h

struct CameraDesc {
  // The file's camera node world transform, decomposed: eye, forward, up (unit).
  Vec3 eye{0, 0, 0}, forward{0, 0, -1}, up{0, 1, 0};
  double xfov_deg = 50;            // full horizontal field of view
  std::optional<double> yfov_deg;  // full vertical, when the file gives it
  std::optional<double> aspect_ratio;
  float znear = 0.001f, zfar = 1000.0f;
  // An orthographic camera (glTF): half the view's height in scene units (ymag); its width
  // follows the image's aspect. Unset: perspective.
  std::optional<double> ortho_half_height;
  Vec3 cs184_dir{0, 0, 1};  // CS184 framing direction c (format doc section 2.2)
  bool present = false;
  // Why the pose or clip planes are unusable (a file's sloppy camera that CS184 framing
  // never reads); empty when they are fine. Rendering with the file's camera refuses it.
  std::string pose_problem;
};

struct Bounds {
  Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
  void extend(Vec3 p) {
    lo = min(lo, p);
    hi = max(hi, p);
  }
  bool empty() const { return lo.x > hi.x; }
  Vec3 center() const { return (lo + hi) * 0.5f; }
  Vec3 diagonal() const { return hi - lo; }
};

struct Scene {
  // Coordinates the ray tracer handles: Embree refuses rays whose origin or direction
  // reaches 1.8e18 (FLT_LARGE) and aborts the process, and CS184 framing puts the eye
  // about a bounding-box diagonal away. 1e12 leaves a margin of a million for both, and
  // is far beyond any real scene (docs/ray-offsets.md).
  static constexpr double kMaxCoordinate = 1e12;
  // Emitted radiance and light intensity, per channel, at most: keeps every honest sample
  // far below kMaxSampleValue (core/render/frame_plan.h), so that a sample beyond it is
  // a worker's lie, not a bright scene.
  static constexpr double kMaxEmission = 1e20;
  // A glTF emissive surface is sampled as a light (and lights the scene: no default
  // environment) when its mean emitted radiance reaches this in some channel: the default
  // environment's radiance, so it is at least as bright as the sky it would replace. Dimmer
  // emission (a helmet's glowing details, a lit label) is glow: reached by paths, not
  // sampled, where a light sample would cost more than the light it finds. CS184
  // emitters are always lights.
  static constexpr float kLampRadiance = 1.0f;
  // An instanced mesh whose material is a lamp is copied into world space per instance
  // (light sampling needs world triangles): at most this many triangles so copied.
  static constexpr size_t kMaxCopiedTriangles = 50'000'000;

  std::string source;  // file it came from
  std::vector<Material> materials;
  std::vector<Mesh> meshes;
  std::vector<Instance> instances;  // placements of Mesh::instanced meshes
  std::vector<Sphere> spheres;
  std::vector<Light> lights;
  std::vector<Texture> textures;
  CameraDesc camera;
  std::vector<std::string> warnings;
  // A glTF scene with no light at all (glow does not count, see kLampRadiance): rendered
  // under a neutral default environment
  // unless --no-default-env (RenderSettings::default_environment), with a warning that
  // is warnings[0].
  bool unlit = false;
  // glTF animations (core/scene/animation.h); null for a scene without any.
  std::shared_ptr<const SceneAnimation> animation;

  // Triangles as rendered: an instanced mesh's once per instance.
  size_t triangle_count() const;
  // Bounds of meshes and spheres that are objects (light shapes excluded), instances
  // placed, as CS184 frames.
  Bounds object_bounds() const;
  // Adds the emitter lights for emission materials and the visible rectangle of each rect
  // light; computes normals; checks every position, radius and the file camera are finite
  // and within kMaxCoordinate (SceneError naming the element otherwise); copies instanced
  // lamps into the world. Loaders call it last.
  void finalize();
  uint32_t add_material(Material m);
  // The material at a surface point with texture coordinates uv (and uv1, of the second
  // set, for textures that read it): its textures applied (base colour,
  // metallic-roughness, emission; not the normal map, which the integrator applies to the
  // shading frame).
  Material textured(const Material& m, Vec2 uv, Vec2 uv1) const;
  Material textured(const Material& m, Vec2 uv) const { return textured(m, uv, uv); }
  // The coverage of mesh `mesh`'s triangle `tri` at barycentrics (b1, b2) (Material's
  // alphaMode), and whether a ray whose uniform number is `u` meets the surface there.
  float opacity_at(const Mesh& mesh, size_t tri, float b1, float b2) const;
  bool covered(const Mesh& mesh, size_t tri, float b1, float b2, float u) const;
};

}  // namespace tessera
