#include "core/camera/camera.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include "core/math/float_math.h"
#include "core/render/settings.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

std::string short_float(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}
std::string short_vec(Vec3 v) {
  return "(" + short_float(v.x) + ", " + short_float(v.y) + ", " + short_float(v.z) + ")";
}

}  // namespace

Camera::Camera(const Scene& scene, const CameraSettings& s, const Bounds* objects)
    : inv_w_(1.0f / float(s.width)),
      inv_h_(1.0f / float(s.height)),
      lens_radius_(s.lens_radius),
      focal_distance_(s.focal_distance) {
  const CameraDesc& c = scene.camera;
  const double deg = M_PI / 180.0;
  const double tx = std::tan(c.xfov_deg * deg / 2);
  double ty = c.yfov_deg ? std::tan(*c.yfov_deg * deg / 2) : tx / c.aspect_ratio.value_or(4.0 / 3.0);
  // The objects' centre, for CS184 framing and a turntable: walked once (every vertex).
  std::optional<Vec3> objects_center;

  if (s.framing == Framing::kCs184) {
    // Eye on the line from the objects' centre along c, 1.5 diagonals away; +Y up.
    Vec3 dir = c.present ? c.cs184_dir : Vec3{0, 0, 1};
    if (std::fabs(dir.y) > 1 - 1e-6f) dir = normalize(Vec3{1e-5f, dir.y, 0});  // phi += 1e-5 (doc 2.2)
    const Bounds b = objects ? *objects : scene.object_bounds();
    const Vec3 target = b.empty() ? Vec3{} : b.center();
    objects_center = target;
    float dist = b.empty() ? 1.0f : 1.5f * length(b.diagonal());
    if (!(dist > 0)) dist = 1;  // the objects are one point: framed as an empty scene
    eye_ = target + dir * dist;
    z_ = normalize(eye_ - target);
    // The eye must differ from the target by about dist: not where float cannot hold the
    // step at the target's coordinates (a 0.5 sphere at 1e11) or square it (a 1e-25 one).
    if (!is_finite(z_) || !(length(eye_ - target) > 0.5f * dist))
      throw SettingsError("--camera", "CS184 framing cannot place the camera: the objects (diagonal " +
                                          short_float(length(b.diagonal())) + ", centred at " + short_vec(target) +
                                          ") are too small to frame in float at their position; scale the scene, "
                                          "or give --camera file");
    x_ = normalize(cross(Vec3{0, 1, 0}, z_));
    y_ = normalize(cross(z_, x_));
    // Fit to an 800x600 screen, then keep the pixel pitch for W x H (doc 2.3).
    double fx = tx, fy = ty;
    if (fx / fy < 4.0 / 3.0) fx = fy * 4.0 / 3.0;
    if (fx / fy > 4.0 / 3.0) fy = fx * 3.0 / 4.0;
    const double screen_dist = 600.0 / (2 * fy);
    tan_h_ = float(s.width / (2 * screen_dist));
    tan_v_ = float(s.height / (2 * screen_dist));
    // The file's clip planes are absolute but the CS184 eye is placed relative to the
    // scene's size: clipping would cut a scaled scene, so this framing does not clip.
  } else {
    if (!c.pose_problem.empty())
      throw SettingsError("--camera", "the file's camera is unusable: " + c.pose_problem +
                                          " (--camera cs184 frames the scene without it)");
    eye_ = c.eye;
    z_ = -c.forward;
    x_ = normalize(cross(c.up, z_));
    y_ = cross(z_, x_);
    tan_v_ = float(ty);
    tan_h_ = float(ty * s.width / s.height);
    tmin_ = c.znear;
    tmax_ = c.zfar;
    clips_ = tmin_ > 0 || tmax_ < 1e30f;
    if (c.ortho_half_height) {
      ortho_h_ = float(*c.ortho_half_height);
      ortho_w_ = ortho_h_ * float(s.width) / float(s.height);
      lens_radius_ = 0;  // (parallel rays: no depth of field)
    }
  }
  const CameraPath::At& p = s.pose;
  if (p.eye || p.target || p.up || p.orbit) {
    Vec3 eye = p.eye.value_or(eye_);
    Vec3 forward = p.target ? normalize(*p.target - eye) : -z_;
    Vec3 up = p.up ? normalize(*p.up) : y_;
    if (p.orbit) {
      if (!p.orbit_center && !objects_center) {
        const Bounds b = objects ? *objects : scene.object_bounds();
        objects_center = b.empty() ? Vec3{} : b.center();
      }
      const Vec3 center = p.orbit_center ? *p.orbit_center : *objects_center;
      // Rodrigues' rotation about the unit axis k by the angle.
      const Vec3 k = p.orbit_axis;
      const float cs = fm::cos(p.orbit_angle), sn = fm::sin(p.orbit_angle);
      auto rotate = [&](Vec3 v) { return v * cs + cross(k, v) * sn + k * (dot(k, v) * (1 - cs)); };
      eye = center + rotate(eye - center);
      forward = rotate(forward);
      up = rotate(up);
    }
    eye_ = eye;
    z_ = -forward;
    Vec3 x = cross(up, z_);
    if (length(x) < 1e-6f) x = cross(std::fabs(z_.y) < 0.9f ? Vec3{0, 1, 0} : Vec3{1, 0, 0}, z_);  // up along the view
    x_ = normalize(x);
    y_ = cross(z_, x_);
  }
  if (p.fov) {
    tan_v_ = float(std::tan(double(*p.fov) * deg / 2));
    tan_h_ = tan_v_ * float(s.width) / float(s.height);
  }
  // Whatever the file, the framing and the path gave: finite, or refused here (Embree
  // aborts the process on a ray that is not).
  // Rays start well inside what Embree takes (about 1.8e18; an orthographic view 1e19 wide
  // put their origins past it): 1e15, a thousand times the scene's own range (CS184 framing
  // of a scene 1e12 across puts its eye beyond 1e12).
  constexpr float kRange = 1e3f * float(Scene::kMaxCoordinate);
  const bool view = ortho_h_ > 0 ? ortho_h_ <= kRange && ortho_w_ > 0 && ortho_w_ <= kRange
                                 : std::isfinite(tan_h_) && std::isfinite(tan_v_) && tan_h_ > 0 && tan_v_ > 0;
  // The lens too: its rays start up to its radius off the eye, and aim through the focal plane.
  // (Bounded as a camera path's keys and -b / -d are: the scene's coordinates' range.)
  constexpr float kLensRange = float(Scene::kMaxCoordinate);
  const bool lens = std::isfinite(lens_radius_) && lens_radius_ <= kLensRange && std::isfinite(focal_distance_) &&
                    (lens_radius_ <= 0 || (focal_distance_ > 0 && focal_distance_ <= kLensRange));
  if (!is_finite(eye_) || !(max_component(abs(eye_)) <= kRange) || !is_finite(x_) || !is_finite(y_) || !is_finite(z_) ||
      !view || !lens)
    throw SettingsError("--camera", "the camera is degenerate: eye " + short_vec(eye_) + ", looking along " +
                                        short_vec(-z_) + ", view " + short_float(2 * tan_h_) + " x " +
                                        short_float(2 * tan_v_) + " at unit distance" +
                                        (lens ? ""
                                              : ", lens radius " + short_float(lens_radius_) + " focused at " +
                                                    short_float(focal_distance_) + " (each at most 1e12)"));
}

Ray Camera::generate(float fx, float fy, Vec2 u_lens) const {
  Ray r;
  r.tmin = tmin_;
  if (ortho_h_ > 0) {  // from a point on the view rectangle, along the view
    r.o = eye_ + x_ * ((2 * fx * inv_w_ - 1) * ortho_w_) + y_ * ((2 * fy * inv_h_ - 1) * ortho_h_);
    r.d = -z_;
    r.tmax = tmax_;
    return r;
  }
  const Vec3 dc{(2 * fx * inv_w_ - 1) * tan_h_, (2 * fy * inv_h_ - 1) * tan_v_, -1};
  if (lens_radius_ <= 0) {
    const Vec3 d = x_ * dc.x + y_ * dc.y + z_ * dc.z;
    const float len = length(d);
    r.o = eye_;
    r.d = d / len;
    r.tmax = tmax_;
    if (clips_) {  // the planes at depth tmin_ and tmax_: along a ray of cosine 1 / |dc|
      const float per_depth = length(dc);
      r.tmin = tmin_ * per_depth;
      r.tmax = tmax_ * per_depth;
    }
    return r;
  }
  const Vec2 disk = square_to_concentric_disk(u_lens);
  const Vec3 lens{lens_radius_ * disk.x, lens_radius_ * disk.y, 0};
  const Vec3 focus = dc * focal_distance_;  // on the plane z_c = -F
  const Vec3 d = focus - lens;
  r.o = eye_ + x_ * lens.x + y_ * lens.y;
  r.d = normalize(x_ * d.x + y_ * d.y + z_ * d.z);
  r.tmax = tmax_;
  if (clips_) {  // d's depth is the focal distance
    const float per_depth = length(d) / focal_distance_;
    r.tmin = tmin_ * per_depth;
    r.tmax = tmax_ * per_depth;
  }
  return r;
}

bool Camera::connect(Vec3 p, Vec2 u_lens, CameraConnection* out) const {
  if (ortho_h_ > 0) return false;
  Vec3 lens_c{0, 0, 0};  // camera space: the lens in the plane z = 0, looking along -z
  if (lens_radius_ > 0) {
    const Vec2 disk = square_to_concentric_disk(u_lens);
    lens_c = {lens_radius_ * disk.x, lens_radius_ * disk.y, 0};
  }
  const Vec3 rel = p - eye_;
  const Vec3 pc{dot(rel, x_), dot(rel, y_), dot(rel, z_)};
  if (!(pc.z < 0)) return false;
  // The film point generate() would aim through this lens point at p: where the line from
  // the lens point through p meets the plane in focus (z = -F), over F. A pinhole: p / -z.
  Vec3 dc;
  if (lens_radius_ > 0) {
    const Vec3 focus = lens_c + (pc - lens_c) * (focal_distance_ / -pc.z);
    dc = focus / focal_distance_;
  } else {
    dc = pc / -pc.z;
  }
  const float fx = (dc.x / tan_h_ + 1) * 0.5f / inv_w_, fy = (dc.y / tan_v_ + 1) * 0.5f / inv_h_;
  if (!(fx >= 0 && fx < 1 / inv_w_ && fy >= 0 && fy < 1 / inv_h_)) return false;
  const Vec3 to_p = pc - lens_c;
  const float dist = length(to_p);
  const float depth = -to_p.z;  // (the lens point is in the plane z = 0)
  if (!(dist > 0) || depth < tmin_ || depth > tmax_) return false;
  const float cos_t = depth / dist;
  const float area = 4 * tan_h_ * tan_v_;
  out->fx = fx;
  out->fy = fy;
  out->lens = eye_ + x_ * lens_c.x + y_ * lens_c.y;
  out->wi = normalize(out->lens - p);
  out->dist = dist;
  out->near = clips_ ? tmin_ / cos_t : 0;
  out->weight = 1 / (area * cos_t * cos_t * cos_t * dist * dist);
  return std::isfinite(out->weight);
}

}  // namespace tessera
