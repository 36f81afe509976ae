// The renderer's scene model: what every loader (COLLADA, glTF) produces and every other
// part of the core consumes. Plain data in world space, +Y up; no file-format concepts.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/math/vec.h"

namespace tessera {

// Material parameters. One struct with a kind tag rather than a class hierarchy: the
// integrator switches on the kind, which keeps the hot loop free of virtual calls.
struct Material {
  enum class Kind : uint8_t { kDiffuse, kMirror, kGlass, kRefraction, kMicrofacet, kEmission };
  Kind kind = Kind::kDiffuse;
  std::string name;
  Rgb reflectance{0.5f};    // diffuse albedo, mirror and glass reflectance
  Rgb transmittance{1.0f};  // glass and refraction
  float ior = 1.5f;         // glass and refraction: interior / exterior
  float alpha = 0.25f;      // microfacet Beckmann roughness
  Rgb eta{0.2f}, k{3.0f};   // microfacet conductor complex index, per channel
  Rgb radiance{0.0f};       // emission
  bool two_sided_emission = true;
  int32_t texture = -1;  // Scene::textures index multiplying `reflectance`, or -1

  bool is_delta() const { return kind == Kind::kMirror || kind == Kind::kGlass || kind == Kind::kRefraction; }
  // True if no BSDF lobe exists: paths end here.
  bool is_black() const { return kind == Kind::kEmission; }
};

struct Mesh {
  std::string name;
  std::vector<Vec3> positions;
  std::vector<uint32_t> indices;  // 3 per triangle
  std::vector<Vec3> normals;      // per vertex: from the file, or area weighted (compute_normals)
  std::vector<Vec2> uvs;          // per vertex texture coordinates, or empty
  bool file_normals = false;      // `normals` came from the file: keep them
  uint32_t material = 0;
  int32_t light = -1;  // index into Scene::lights when the mesh emits

  size_t triangle_count() const { return indices.size() / 3; }
  void compute_normals();
};

struct Sphere {
  std::string name;
  Vec3 center;
  float radius = 1;
  uint32_t material = 0;
  int32_t light = -1;
};

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

  bool is_delta() const { return kind == Kind::kPoint || kind == Kind::kSpot || kind == Kind::kDirectional; }
  bool is_infinite() const {
    return kind == Kind::kDirectional || kind == Kind::kAmbient || kind == Kind::kEnvironment;
  }
};

// An RGB texture in linear values, bilinearly filtered, with glTF's wrap modes.
struct Texture {
  enum class Wrap : uint8_t { kRepeat, kClamp, kMirror };
  int width = 0, height = 0;
  std::vector<Rgb> texels;  // row-major, row 0 at v = 0
  Wrap wrap_s = Wrap::kRepeat, wrap_t = Wrap::kRepeat;
  Rgb sample(Vec2 uv) const;
};

struct SceneAnimation;  // core/scene/animation.h

struct CameraDesc {
  // The file's camera node world transform, decomposed: eye, forward, up (unit).
  Vec3 eye{0, 0, 0}, forward{0, 0, -1}, up{0, 1, 0};
  double xfov_deg = 50;            // full horizontal field of view
  std::optional<double> yfov_deg;  // full vertical, when the file gives it
  std::optional<double> aspect_ratio;
  float znear = 0.001f, zfar = 1000.0f;
  Vec3 cs184_dir{0, 0, 1};  // CS184 framing direction c (format doc section 2.2)
  bool present = false;
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

  std::string source;  // file it came from
  std::vector<Material> materials;
  std::vector<Mesh> meshes;
  std::vector<Sphere> spheres;
  std::vector<Light> lights;
  std::vector<Texture> textures;
  CameraDesc camera;
  std::vector<std::string> warnings;
  // A glTF scene with no light at all: rendered under a neutral default environment
  // unless --no-default-env (RenderSettings::default_environment), with a warning.
  bool unlit = false;
  // glTF animations (core/scene/animation.h); null for a scene without any.
  std::shared_ptr<const SceneAnimation> animation;

  size_t triangle_count() const;
  // Bounds of meshes and spheres that are objects (light shapes excluded), as CS184 frames.
  Bounds object_bounds() const;
  // Adds the emitter lights for emission materials and the visible rectangle of each rect
  // light; computes normals; checks every position, radius and the file camera are finite
  // and within kMaxCoordinate (SceneError naming the element otherwise). Loaders call it
  // last.
  void finalize();
  uint32_t add_material(Material m);
};

}  // namespace tessera
