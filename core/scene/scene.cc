#include "core/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/scene/scene_error.h"

namespace tessera {

void Mesh::compute_normals() {
  normals.assign(positions.size(), Vec3{});
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    const uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
    // Unnormalised cross product: weights each face by its area.
    const Vec3 n = cross(positions[b] - positions[a], positions[c] - positions[a]);
    normals[a] += n;
    normals[b] += n;
    normals[c] += n;
  }
  for (Vec3& n : normals) {
    const float len = length(n);
    n = len > 0 && std::isfinite(len) ? n / len : Vec3{};  // zero: use the geometric normal
  }
}

size_t Scene::triangle_count() const {
  size_t n = 0;
  for (const Mesh& m : meshes)
    if (!m.instanced) n += m.triangle_count();
  for (const Instance& in : instances) n += meshes[in.mesh].triangle_count();
  return n;
}

Bounds Scene::object_bounds() const {
  Bounds b;
  for (const Mesh& m : meshes) {
    if (m.instanced || (m.light >= 0 && lights[m.light].kind == Light::Kind::kRect)) continue;
    for (uint32_t i : m.indices) b.extend(m.positions[i]);
  }
  // Each instanced mesh's vertices that triangles use, found once however many instances.
  std::vector<std::vector<uint32_t>> used(meshes.size());
  for (const Instance& in : instances) {
    const Mesh& m = meshes[in.mesh];
    std::vector<uint32_t>& u = used[in.mesh];
    if (u.empty()) {
      u = m.indices;
      std::sort(u.begin(), u.end());
      u.erase(std::unique(u.begin(), u.end()), u.end());
    }
    for (uint32_t i : u) b.extend(in.point(m.positions[i]));
  }
  for (const Sphere& s : spheres) {
    b.extend(s.center - Vec3{s.radius, s.radius, s.radius});
    b.extend(s.center + Vec3{s.radius, s.radius, s.radius});
  }
  return b;
}

uint32_t Scene::add_material(Material m) {
  materials.push_back(std::move(m));
  return uint32_t(materials.size() - 1);
}

namespace {

std::string describe(Vec3 p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%g, %g, %g)", double(p.x), double(p.y), double(p.z));
  return buf;
}

bool unplaced(const Mesh& m) { return m.instanced; }  // (its instances, if any, are not lamps)
bool unplaced(const Sphere&) { return false; }

// Light sampling needs a lamp's triangles in world space: an instanced mesh whose material
// is a lamp becomes one world-space copy per instance (the first takes the mesh's place).
template <typename IsLight>
void copy_instanced_lamps(Scene& s, const IsLight& is_light) {
  std::vector<std::vector<const Instance*>> of(s.meshes.size());
  for (const Instance& in : s.instances) of[in.mesh].push_back(&in);
  std::vector<bool> copied(s.meshes.size());
  size_t triangles = 0;
  for (size_t i = 0; i < s.meshes.size(); ++i) {
    // (One with no instance stays unplaced: nothing renders it, nothing samples it.)
    if (!s.meshes[i].instanced || of[i].empty() || !is_light(s.materials[s.meshes[i].material])) continue;
    copied[i] = true;
    const Mesh object = std::move(s.meshes[i]);
    triangles += object.triangle_count() * of[i].size();
    if (triangles > Scene::kMaxCopiedTriangles)
      throw SceneError(s.source, "mesh '" + object.name + "'",
                       "an emissive instanced mesh is copied per instance to be sampled as a light, and " +
                           std::to_string(of[i].size()) + " instances make more than the 50 M triangle limit");
    for (size_t k = 0; k < of[i].size(); ++k) {
      const Instance& in = *of[i][k];
      Mesh m = object;
      m.instanced = false;
      for (Vec3& p : m.positions) p = in.point(p);
      for (Vec3& n : m.normals) {
        n = in.normal_to_world(n);
        const float len = length(n);
        n = len > 0 && std::isfinite(len) ? n / len : Vec3{};
      }
      if (in.mirrored)
        for (size_t t = 0; t + 2 < m.indices.size(); t += 3) std::swap(m.indices[t + 1], m.indices[t + 2]);
      if (k == 0)
        s.meshes[i] = std::move(m);
      else
        s.meshes.push_back(std::move(m));
    }
  }
  std::erase_if(s.instances, [&](const Instance& in) { return copied[in.mesh]; });
}

}  // namespace

void Scene::finalize() {
  // Geometry the ray tracer cannot handle is refused here, for every loader, before any
  // renderer (or a farm's coordinator at submit) builds on it.
  auto in_range = [](double v) { return std::isfinite(v) && std::abs(v) <= kMaxCoordinate; };
  auto check_point = [&](Vec3 p, const std::string& element, const std::string& what) {
    if (!in_range(p.x) || !in_range(p.y) || !in_range(p.z))
      throw SceneError(source, element,
                       what + " " + describe(p) + " is not finite or outside +-1e12, the range the ray tracer handles");
  };
  for (const Mesh& m : meshes)
    for (size_t v = 0; v < m.positions.size(); ++v)
      check_point(m.positions[v], "mesh '" + m.name + "'", "vertex " + std::to_string(v));
  std::vector<std::optional<Bounds>> boxes(meshes.size());  // each instanced mesh's, once
  for (size_t k = 0; k < instances.size(); ++k) {           // each placed box's corners
    const Instance& in = instances[k];
    std::optional<Bounds>& box_of = boxes[in.mesh];
    if (!box_of) {
      box_of.emplace();
      for (const Vec3& p : meshes[in.mesh].positions) box_of->extend(p);
    }
    const Bounds& box = *box_of;
    if (box.empty()) continue;
    for (int c = 0; c < 8; ++c)
      check_point(in.point({c & 1 ? box.hi.x : box.lo.x, c & 2 ? box.hi.y : box.lo.y, c & 4 ? box.hi.z : box.lo.z}),
                  "mesh '" + meshes[in.mesh].name + "' instance " + std::to_string(k), "bounding box corner");
  }
  for (const Sphere& sp : spheres) {
    check_point(sp.center, "sphere '" + sp.name + "'", "centre");
    if (!(sp.radius > 0) || !in_range(sp.radius))
      throw SceneError(source, "sphere '" + sp.name + "'",
                       "radius " + std::to_string(sp.radius) + " must be positive and at most 1e12");
  }
  for (const Light& l : lights) {
    check_point(l.position, "light '" + l.name + "'", "position");
    check_point(l.edge_x, "light '" + l.name + "'", "edge");
    check_point(l.edge_y, "light '" + l.name + "'", "edge");
  }
  if (camera.present) check_point(camera.eye, "camera", "eye");
  auto check_emission = [&](Rgb c, const std::string& element) {
    for (const double v : {double(c.r), double(c.g), double(c.b)})
      if (!std::isfinite(v) || v < 0 || v > kMaxEmission)
        throw SceneError(source, element,
                         "emission " + std::to_string(v) + " must be finite, non-negative and at most 1e20");
  };
  for (const Light& l : lights) {
    check_emission(l.color, "light '" + l.name + "'");
    // A point or spot light's falloff divides its colour by c + l d + q d^2: tiny
    // coefficients (c = 1e-38) passed the bound above and made every sample infinite.
    if (l.kind == Light::Kind::kPoint || l.kind == Light::Kind::kSpot) {
      const double at_unit = double(l.color.max()) / (double(l.att_constant) + l.att_linear + l.att_quadratic);
      if (!(at_unit <= kMaxEmission)) {
        char v[32];
        std::snprintf(v, sizeof v, "%g", at_unit);
        throw SceneError(source, "light '" + l.name + "'",
                         std::string("emission over attenuation at unit distance, ") + v +
                             ", must be at most 1e20 (attenuation coefficients too small for its colour)");
      }
    }
  }
  for (const Material& m : materials) check_emission(m.radiance, "material '" + m.name + "'");
  // Rect lights are also geometry: a one-sided emitter that camera rays see and that
  // blocks other rays (format doc 3.3, with the physical radiance `color`).
  for (size_t i = 0; i < lights.size(); ++i) {
    Light& l = lights[i];
    if (l.kind != Light::Kind::kRect) continue;
    Material m;
    m.kind = Material::Kind::kEmission;
    m.name = l.name + "-emitter";
    m.radiance = l.color;
    m.two_sided_emission = false;
    Mesh mesh;
    mesh.name = l.name;
    const Vec3 hx = l.edge_x * 0.5f, hy = l.edge_y * 0.5f;
    mesh.positions = {l.position - hx - hy, l.position + hx - hy, l.position + hx + hy, l.position - hx + hy};
    // Wind so the geometric normal is the facing direction.
    if (dot(cross(l.edge_x, l.edge_y), l.normal) >= 0)
      mesh.indices = {0, 1, 2, 0, 2, 3};
    else
      mesh.indices = {0, 2, 1, 0, 3, 2};
    mesh.material = add_material(std::move(m));
    mesh.light = int32_t(i);
    l.shape = uint32_t(meshes.size());
    meshes.push_back(std::move(mesh));
  }
  // Emitters (CS184's) and glTF surfaces bright enough to be lamps (kLampRadiance) are
  // sampled as area lights; dimmer glTF emission is glow, reached by paths only.
  auto is_light = [this](const Material& m) {
    if (!m.emits()) return false;
    if (m.kind == Material::Kind::kEmission) return true;
    const Rgb mean =
        m.radiance * (m.emissive_texture.active() ? textures[size_t(m.emissive_texture.index)].mean() : Rgb(1.0f));
    return mean.max() >= kLampRadiance;
  };
  auto add_emitter = [&](auto& shapes, Light::Kind kind) {
    for (size_t i = 0; i < shapes.size(); ++i) {
      auto& shape = shapes[i];
      const Material& m = materials[shape.material];
      if (shape.light >= 0 || unplaced(shape) || !is_light(m)) continue;
      Light l;
      l.kind = kind;
      l.name = shape.name;
      l.color = m.radiance;
      l.shape = uint32_t(i);
      l.two_sided = m.two_sided_emission;
      shape.light = int32_t(lights.size());
      lights.push_back(l);
    }
  };
  copy_instanced_lamps(*this, is_light);
  add_emitter(meshes, Light::Kind::kMesh);
  add_emitter(spheres, Light::Kind::kSphere);
  for (Mesh& mesh : meshes)
    if (mesh.flat)
      mesh.normals.assign(mesh.positions.size(), Vec3{});
    else if (!mesh.file_normals)
      mesh.compute_normals();
}

namespace {

int wrap(int i, int n, Texture::Wrap mode) {
  switch (mode) {
    case Texture::Wrap::kClamp:
      return std::clamp(i, 0, n - 1);
    case Texture::Wrap::kMirror: {
      const int period = 2 * n;
      int m = ((i % period) + period) % period;
      return m < n ? m : period - 1 - m;
    }
    case Texture::Wrap::kRepeat:
      break;
  }
  return ((i % n) + n) % n;
}

}  // namespace

const std::array<float, 256>& byte_fractions() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int c = 0; c < 256; ++c) t[size_t(c)] = c / 255.0f;
    return t;
  }();
  return table;
}

float Texture::texel_alpha(size_t i) const {
  if (rgba8) return rgba8_translucent ? byte_fractions()[(*rgba8)[4 * i + 3]] : 1.0f;
  return alpha.empty() ? 1.0f : alpha[i];
}

Rgb Texture::mean() const {
  double r = 0, g = 0, b = 0;
  const size_t n = rgba8 ? size() : texels.size();
  for (size_t i = 0; i < n; ++i) {
    const Rgb t = texel(i);
    r += t.r;
    g += t.g;
    b += t.b;
  }
  const double d = n == 0 ? 1 : double(n);
  return Rgb(float(r / d), float(g / d), float(b / d));
}

namespace {

// Bilinear lookup in a row-major grid of texels (texel(i): the i-th, decoded), with the
// texture's wrap modes.
template <typename Texel>
auto bilinear(const Texture& tex, const Texel& texel, Vec2 uv) {
  // Texel centres at (i + 0.5) / n, as OpenGL samples.
  const float x = uv.x * float(tex.width) - 0.5f, y = uv.y * float(tex.height) - 0.5f;
  if (!std::isfinite(x) || !std::isfinite(y)) return texel(0);
  // Guard huge coordinates before converting to int.
  auto to_int = [](float f) { return int(std::fmod(double(f), 1 << 24)); };
  auto at = [&](int i, int j) {
    return texel(size_t(wrap(j, tex.height, tex.wrap_t)) * size_t(tex.width) + size_t(wrap(i, tex.width, tex.wrap_s)));
  };
  // magFilter NEAREST: the texel containing uv (centres at (i + 0.5) / n, so round x and y).
  if (tex.nearest) return at(to_int(std::floor(x + 0.5f)), to_int(std::floor(y + 0.5f)));
  const float fx = std::floor(x), fy = std::floor(y);
  const float tx = x - fx, ty = y - fy;
  const int ix = to_int(fx), iy = to_int(fy);
  return at(ix, iy) * ((1 - tx) * (1 - ty)) + at(ix + 1, iy) * (tx * (1 - ty)) + at(ix, iy + 1) * ((1 - tx) * ty) +
         at(ix + 1, iy + 1) * (tx * ty);
}

}  // namespace

Rgb Texture::sample(Vec2 uv) const {
  if (width <= 0 || height <= 0) return Rgb(1);
  if (rgba8) {
    const uint8_t* bytes = rgba8->data();
    const std::array<float, 256>& d = *decode;
    return bilinear(
        *this, [bytes, &d](size_t i) { return Rgb(d[bytes[4 * i]], d[bytes[4 * i + 1]], d[bytes[4 * i + 2]]); }, uv);
  }
  return bilinear(
      *this, [this](size_t i) { return texels[i]; }, uv);
}

float Texture::sample_alpha(Vec2 uv) const {
  if (width <= 0 || height <= 0) return 1;
  if (rgba8) {
    if (!rgba8_translucent) return 1;
    const uint8_t* bytes = rgba8->data();
    const std::array<float, 256>& d = byte_fractions();
    return bilinear(
        *this, [bytes, &d](size_t i) { return d[bytes[4 * i + 3]]; }, uv);
  }
  if (alpha.size() != texels.size()) return 1;
  return bilinear(
      *this, [this](size_t i) { return alpha[i]; }, uv);
}

}  // namespace tessera

namespace tessera {

Material Scene::textured(const Material& m, Vec2 uv, Vec2 uv1) const {
  Material out = m;
  auto coords = [&](const TextureRef& t) { return t.map(t.set ? uv1 : uv); };
  auto at = [&](const TextureRef& t) { return textures[size_t(t.index)].sample(coords(t)); };
  if (m.texture.active()) out.reflectance *= at(m.texture);
  if (m.metal_rough_texture.active()) {
    const Rgb mr = at(m.metal_rough_texture);
    out.roughness = std::clamp(m.roughness * mr.g, 0.0f, 1.0f);
    out.alpha = out.roughness * out.roughness;
    out.metallic = std::clamp(m.metallic * mr.b, 0.0f, 1.0f);
  }
  if (m.emissive_texture.active()) out.radiance *= at(m.emissive_texture);
  if (m.transmission_texture.active())
    out.transmission = std::clamp(m.transmission * at(m.transmission_texture).r, 0.0f, 1.0f);
  if (m.specular_texture.active())
    out.specular *= textures[size_t(m.specular_texture.index)].sample_alpha(coords(m.specular_texture));
  if (m.specular_color_texture.active()) out.specular_color *= at(m.specular_color_texture);
  if (m.clearcoat_texture.active()) out.clearcoat = std::clamp(m.clearcoat * at(m.clearcoat_texture).r, 0.0f, 1.0f);
  if (m.clearcoat_roughness_texture.active()) {
    out.clearcoat_roughness = std::clamp(m.clearcoat_roughness * at(m.clearcoat_roughness_texture).g, 0.0f, 1.0f);
    out.clearcoat_alpha = out.clearcoat_roughness * out.clearcoat_roughness;
  }
  if (m.sheen_color_texture.active()) out.sheen_color *= at(m.sheen_color_texture);
  if (m.sheen_roughness_texture.active())
    out.sheen_roughness *=
        textures[size_t(m.sheen_roughness_texture.index)].sample_alpha(coords(m.sheen_roughness_texture));
  return out;
}

float Scene::opacity_at(const Mesh& mesh, size_t tri, float b1, float b2) const {
  const Material& m = materials[mesh.material];
  float a = m.opacity;
  const TextureRef& t = m.texture;
  if (t.active() && textures[size_t(t.index)].has_alpha() && !mesh.uv_set(t.set).empty())
    a *= textures[size_t(t.index)].sample_alpha(t.map(mesh.uv_at(tri, b1, b2, t.set)));
  if (!mesh.color_alpha.empty()) {
    const uint32_t* i = &mesh.indices[3 * tri];
    a *= mesh.color_alpha[i[0]] * (1 - b1 - b2) + mesh.color_alpha[i[1]] * b1 + mesh.color_alpha[i[2]] * b2;
  }
  return a;
}

bool Scene::covered(const Mesh& mesh, size_t tri, float b1, float b2, float u) const {
  switch (materials[mesh.material].alpha_mode) {
    case Material::AlphaMode::kOpaque:
      return true;
    case Material::AlphaMode::kMask:
      return opacity_at(mesh, tri, b1, b2) >= materials[mesh.material].alpha_cutoff;
    case Material::AlphaMode::kBlend:
      return u < opacity_at(mesh, tri, b1, b2);
  }
  return true;
}

}  // namespace tessera
