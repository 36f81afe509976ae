#include "core/scene/gltf/gltf_lights_cameras.h"

#include <cmath>

#include "core/scene/animation.h"

namespace tessera {
namespace {

// 1 W = 683 lm at 555 nm: KHR_lights_punctual's photometric units to our radiometric RGB.
constexpr double kLumensPerWatt = 683.0;

}  // namespace

std::optional<int> gltf_node_light(const GltfContext& ctx, const tinygltf::Node& node, const std::string& node_el) {
  auto it = node.extensions.find("KHR_lights_punctual");
  if (it == node.extensions.end()) return std::nullopt;
  if (!it->second.Has("light") || !it->second.Get("light").IsInt())
    ctx.fail(node_el, "KHR_lights_punctual without a light index");
  return it->second.Get("light").GetNumberAsInt();
}

void add_gltf_light(GltfContext& ctx, int index, const Mat4& w, const Mat4& orientation, const std::string& node_el) {
  if (index < 0 || size_t(index) >= ctx.model.lights.size())
    ctx.fail(node_el, "light " + std::to_string(index) + " does not exist");
  const tinygltf::Light& g = ctx.model.lights[size_t(index)];
  const std::string el = "KHR_lights_punctual.lights[" + std::to_string(index) + "]";
  Rgb color(1.0f);
  if (g.color.size() >= 3) color = Rgb(float(g.color[0]), float(g.color[1]), float(g.color[2]));
  if (!(g.intensity >= 0) || !std::isfinite(g.intensity)) ctx.fail(el, "intensity must be >= 0");
  Light l;
  l.name = g.name.empty() ? "light" + std::to_string(index) : g.name;
  // Point and spot intensity is in candela (lm/sr), directional in lux (lm/m^2):
  // divided by 683 lm/W they become W/sr and W/m^2.
  l.color = color * float(g.intensity / kLumensPerWatt);
  if (g.type == "directional") {
    l.kind = Light::Kind::kDirectional;
  } else if (g.type == "point" || g.type == "spot") {
    l.kind = g.type == "point" ? Light::Kind::kPoint : Light::Kind::kSpot;
    l.att_constant = 0;
    l.att_linear = 0;
    l.att_quadratic = 1;  // physical inverse square
    if (g.type == "spot") {
      if (!(g.spot.outerConeAngle > g.spot.innerConeAngle && g.spot.innerConeAngle >= 0 &&
            g.spot.outerConeAngle <= M_PI / 2 + 1e-6))
        ctx.fail(el, "needs 0 <= innerConeAngle < outerConeAngle <= pi/2");
      l.cos_inner = float(std::cos(g.spot.innerConeAngle));
      l.cos_outer = float(std::cos(g.spot.outerConeAngle));
    }
    if (g.range > 0) ctx.warn_once(el + ": range is ignored (inverse-square falloff)");
  } else {
    ctx.fail(el, "unknown light type '" + g.type + "'");
  }
  place_light(l, w, orientation);
  if (!placed(l)) ctx.fail(node_el, "light transform is degenerate");
  ctx.scene.lights.push_back(l);
}

void add_gltf_camera(GltfContext& ctx, int index, const Mat4& w, const std::string& node_el) {
  if (size_t(index) >= ctx.model.cameras.size())
    ctx.fail(node_el, "camera " + std::to_string(index) + " does not exist");
  if (ctx.scene.camera.present) return;  // the first camera in the scene's node order wins
  const tinygltf::Camera& c = ctx.model.cameras[size_t(index)];
  const std::string el = "cameras[" + std::to_string(index) + "]";
  if (c.type == "orthographic") {
    const tinygltf::OrthographicCamera& o = c.orthographic;
    if (!(std::isfinite(o.xmag) && std::isfinite(o.ymag) && o.xmag != 0 && o.ymag != 0 &&
          std::fabs(o.xmag) <= Scene::kMaxCoordinate && std::fabs(o.ymag) <= Scene::kMaxCoordinate))
      ctx.fail(el, "orthographic xmag and ymag must be finite, not zero and within +-1e12");
    if (!(o.znear >= 0 && o.zfar > o.znear && std::isfinite(o.zfar)))
      ctx.fail(el, "orthographic needs 0 <= znear < zfar");
    CameraDesc& d = ctx.scene.camera;
    d.present = true;
    d.ortho_half_height = std::fabs(o.ymag);
    d.aspect_ratio = std::fabs(o.xmag / o.ymag);
    d.znear = float(o.znear);
    d.zfar = float(o.zfar);
    place_camera(d, w);
    if (!is_finite(d.forward) || !is_finite(d.up)) ctx.fail(node_el, "camera transform is degenerate");
    return;
  }
  if (c.type != "perspective") ctx.fail(el, "unknown camera type '" + c.type + "'");
  const double yfov = c.perspective.yfov * 180 / M_PI;
  if (!(yfov > 0 && yfov < 180)) ctx.fail(el, "yfov must be in (0, pi)");
  CameraDesc& d = ctx.scene.camera;
  d.present = true;
  d.yfov_deg = yfov;
  if (c.perspective.aspectRatio > 0) d.aspect_ratio = c.perspective.aspectRatio;
  d.xfov_deg = 2 * std::atan(std::tan(c.perspective.yfov / 2) * d.aspect_ratio.value_or(4.0 / 3.0)) * 180 / M_PI;
  d.znear = float(c.perspective.znear > 0 ? c.perspective.znear : 0.001);
  d.zfar = float(c.perspective.zfar > c.perspective.znear ? c.perspective.zfar : 1e30);
  place_camera(d, w);
  if (!is_finite(d.forward) || !is_finite(d.up)) ctx.fail(node_el, "camera transform is degenerate");
}

void frame_gltf_scene(GltfContext& ctx) {
  const Bounds b = ctx.scene.object_bounds();
  const Vec3 c = b.center();
  const float r = 0.5f * length(b.diagonal());
  CameraDesc& d = ctx.scene.camera;
  d.present = true;
  d.yfov_deg = 40;
  // No clipping: the default far plane (1000) cut a model whose framing puts the eye
  // further away (a 480-unit Cornell box showed as a dot).
  d.znear = 0.001f;
  d.zfar = 1e30f;
  // A three-quarter view, as glTF viewers frame a file without a camera: from the front
  // (+Z) right (+X), 45 degrees round and 30 degrees up, so that a model lying on the
  // ground plane is seen from above rather than edge-on.
  const float el = 30 * kPi / 180, az = 45 * kPi / 180;
  const Vec3 dir{std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
  d.eye = c + dir * (r / std::sin(20 * kPi / 180) * 1.05f);
  d.forward = -dir;
  d.up = {0, 1, 0};
  d.cs184_dir = dir;
  ctx.scene.warnings.push_back(ctx.path +
                               ": no camera; framing the scene's bounds from a three-quarter view (from the front "
                               "right, 30 degrees above)");
}

}  // namespace tessera
