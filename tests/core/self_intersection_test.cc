// Self-intersection as a property (docs/ray-offsets.md): a ray leaving a surface never meets
// that surface again, whatever the surface's position, orientation and scale.
//
// Each case is one lone primitive, diffuse, lit by one point light with inverse-square
// falloff on the side the camera looks from. Nothing else is in the scene, so every shadow
// ray is unoccluded and every continuation ray escapes: the radiance of a camera ray that
// hits the primitive at q is exactly rho / pi x I cos(theta) / r^2 (one shadow ray, no
// noise). A shadow ray that hits its own surface makes it black; a continuation ray that
// does so adds light and is counted in RayCounters::self_hits.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <random>
#include <sstream>
#include <string>

#include "core/accel/accel.h"
#include "core/light/lights.h"
#include "core/render/integrator.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr float kAlbedo = 0.5f;

struct D3 {
  double x = 0, y = 0, z = 0;
};
D3 operator+(D3 a, D3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
D3 operator-(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
D3 operator*(D3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 cross(D3 a, D3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double norm(D3 a) { return std::sqrt(dot(a, a)); }
D3 unit(D3 a) { return a * (1 / norm(a)); }
D3 d3(Vec3 v) { return {v.x, v.y, v.z}; }
Vec3 f3(D3 v) { return {float(v.x), float(v.y), float(v.z)}; }

// A primitive to test: a triangle (three float vertices) or a sphere.
struct Shape {
  bool sphere = false;
  Vec3 v[3];                   // triangle
  Vec3 center;                 // sphere
  float radius = 0;            // sphere
  double scale = 1;            // its size, for placing the light and the camera
  bool aim_at_origin = false;  // sphere: the first ray hits the point (0, 0, 0) on it
  // A triangle stored in object space (`obj`) and placed by an instance (v = place x obj).
  std::optional<Mat4> place;
  Vec3 obj[3];
  std::string what;  // for failure messages
};

Scene scene_of(const Shape& s, D3 light_pos, double intensity) {
  Scene scene;
  Material m;
  m.kind = Material::Kind::kDiffuse;
  m.reflectance = Rgb(kAlbedo);
  scene.materials.push_back(m);
  if (s.sphere) {
    scene.spheres.push_back(Sphere{"s", s.center, s.radius, 0, -1});
  } else {
    Mesh mesh;
    mesh.name = "t";
    mesh.positions = {s.v[0], s.v[1], s.v[2]};
    mesh.indices = {0, 1, 2};
    if (s.place) {
      mesh.positions = {s.obj[0], s.obj[1], s.obj[2]};
      mesh.instanced = true;
      scene.instances.push_back(*Instance::make(0, *s.place));
    }
    scene.meshes.push_back(mesh);
  }
  Light l;
  l.kind = Light::Kind::kPoint;
  l.position = f3(light_pos);
  l.color = Rgb(float(intensity));
  l.att_constant = 0;
  l.att_quadratic = 1;
  scene.lights.push_back(l);
  scene.finalize();
  return scene;
}

struct Outcome {
  int rays = 0, wrong = 0;
  uint64_t self_hits = 0;
  std::string first_wrong;
};

// Shoots `n` camera rays at random points of the primitive from the lit side and checks each
// radiance against the exact value.
Outcome check_shape(const Shape& s, std::mt19937_64& rng, int n) {
  std::uniform_real_distribution<double> u01(0, 1);
  // The surface point aimed at, its unit normal (toward the camera and light) and a frame.
  auto pick = [&](D3* q, D3* normal) {
    if (s.sphere) {
      const double z = 2 * u01(rng) - 1, phi = 2 * kPi * u01(rng), r = std::sqrt(std::max(0.0, 1 - z * z));
      *normal = {r * std::cos(phi), r * std::sin(phi), z};
      *q = d3(s.center) + *normal * s.radius;
    } else {
      double b1 = 0.05 + 0.9 * u01(rng), b2 = 0.05 + 0.9 * u01(rng);
      if (b1 + b2 > 0.95) {
        b1 = 1 - b1;
        b2 = 1 - b2;
      }
      b1 = std::clamp(b1, 0.02, 0.96);
      b2 = std::clamp(b2, 0.02, 0.96 - b1);
      const D3 p0 = d3(s.v[0]), p1 = d3(s.v[1]), p2 = d3(s.v[2]);
      *q = p0 + (p1 - p0) * b1 + (p2 - p0) * b2;
      *normal = unit(cross(p1 - p0, p2 - p0));
      if (u01(rng) < 0.5) *normal = *normal * -1;  // either face: diffuse is two-sided
    }
  };
  // Fixed per shape for a triangle (one light, one side); per ray for a sphere.
  D3 q, normal;
  pick(&q, &normal);
  if (s.aim_at_origin) {
    q = {0, 0, 0};
    normal = unit(q - d3(s.center));
  }
  auto away = [&](D3 nrm, double cos_min) {  // a unit direction within acos(cos_min) of nrm
    const D3 a = std::fabs(nrm.x) < 0.9 ? D3{1, 0, 0} : D3{0, 1, 0};
    const D3 t = unit(cross(nrm, a)), b = cross(nrm, t);
    const double c = cos_min + (1 - cos_min) * u01(rng), sn = std::sqrt(1 - c * c), phi = 2 * kPi * u01(rng);
    return unit(nrm * c + t * (sn * std::cos(phi)) + b * (sn * std::sin(phi)));
  };
  Outcome out;
  const D3 light_dir = away(normal, 0.3);
  D3 light = q + light_dir * (1.5 * s.scale);
  const double intensity = s.scale * s.scale;  // irradiance ~1 at any scale
  Scene scene = scene_of(s, light, intensity);
  const Accel accel(scene);
  const LightSet lights(scene);
  RenderSettings rs;
  rs.max_depth = 6;
  const Integrator integrator(scene, accel, lights, rs);
  light = d3(scene.lights[0].position);  // as stored (rounded to float)
  for (int i = 0; i < n; ++i) {
    // A few rays at the chosen point, then random ones.
    if (i >= 4) pick(&q, &normal);
    if (s.sphere && dot(unit(light - q), normal) < 0.2) continue;  // light not above this point
    if (!s.sphere && i >= 4) {
      // Keep the triangle's lit face: the normal is the face the light is on.
      if (dot(normal, light - q) < 0) normal = normal * -1;
    }
    const D3 eye = q + away(normal, 0.2) * (3 * s.scale);
    Ray ray;
    ray.o = f3(eye);
    ray.d = f3(unit(q - d3(ray.o)));
    ray.tmin = 0;
    ray.tmax = std::numeric_limits<float>::infinity();
    Sampler sampler(1, uint64_t(i), 0);
    RayCounters counters;
    const Rgb L = integrator.radiance(ray, sampler, counters);
    out.self_hits += counters.self_hits;
    ++out.rays;
    const D3 to_light = light - q;
    const double r2 = dot(to_light, to_light), cos_l = std::fabs(dot(unit(to_light), normal));
    const double expected = kAlbedo / kPi * intensity * cos_l / r2;
    if (!(std::fabs(L.r - expected) <= 0.02 * expected)) {
      ++out.wrong;
      if (out.first_wrong.empty()) {
        std::ostringstream m;
        m << s.what << ": radiance " << L.r << ", expected " << expected << " (self-hits " << counters.self_hits << ")";
        out.first_wrong = m.str();
      }
    }
  }
  return out;
}

// A random unit vector, or one along a coordinate axis (an axis-aligned plane).
D3 random_normal(std::mt19937_64& rng, bool axis_aligned) {
  std::uniform_real_distribution<double> u(-1, 1);
  if (axis_aligned) {
    D3 n{0, 0, 0};
    const int a = int(rng() % 3);
    (a == 0 ? n.x : a == 1 ? n.y : n.z) = rng() % 2 ? 1 : -1;
    return n;
  }
  for (;;) {
    const D3 v{u(rng), u(rng), u(rng)};
    const double l = norm(v);
    if (l > 0.1 && l <= 1) return v * (1 / l);
  }
}

// A well-shaped random triangle of size `scale` about `center` in the plane with normal nrm.
// With `vertex_at_center` one vertex is exactly the centre (the origin, when centre is 0).
Shape random_triangle(std::mt19937_64& rng, D3 center, double scale, D3 nrm, bool vertex_at_center) {
  std::uniform_real_distribution<double> u(-1, 1);
  const D3 a = std::fabs(nrm.x) < 0.9 ? D3{1, 0, 0} : D3{0, 1, 0};
  const D3 t = unit(cross(nrm, a)), b = cross(nrm, t);
  Shape s;
  s.scale = scale;
  for (;;) {
    for (int k = 0; k < 3; ++k) {
      const D3 off = (vertex_at_center && k == 0) ? D3{} : (t * u(rng) + b * u(rng)) * scale;
      D3 p = center + off;
      // In an axis-aligned plane, the coordinate along the axis is the centre's, exactly.
      if (nrm.x != 0 && nrm.y == 0 && nrm.z == 0) p.x = center.x;
      if (nrm.y != 0 && nrm.x == 0 && nrm.z == 0) p.y = center.y;
      if (nrm.z != 0 && nrm.x == 0 && nrm.y == 0) p.z = center.z;
      s.v[k] = f3(p);
    }
    const D3 e1 = d3(s.v[1]) - d3(s.v[0]), e2 = d3(s.v[2]) - d3(s.v[0]);
    const double area2 = norm(cross(e1, e2));
    // Not a sliver: every angle of reasonable size (area against the longest edge squared).
    const double longest = std::max({norm(e1), norm(e2), norm(d3(s.v[2]) - d3(s.v[1]))});
    if (area2 > 0.2 * longest * longest) return s;
  }
}

std::string describe(const char* kind, D3 c, double scale) {
  std::ostringstream m;
  m << kind << " of size " << scale << " at (" << c.x << ", " << c.y << ", " << c.z << ")";
  return m.str();
}

// Positions tried at each scale: the origin, near it (a small fraction of the size off each
// axis), a few sizes away, and far from the origin (1e5 and 1e5 + a random offset).
std::vector<D3> positions(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<D3> p = {{0, 0, 0},
                       {1e-3 * scale, -2e-3 * scale, 5e-4 * scale},
                       {u(rng) * 4 * scale, u(rng) * 4 * scale, u(rng) * 4 * scale},
                       {1e5, 1e5, 1e5},
                       {1e5 + u(rng) * 1e3, -1e5 + u(rng) * 1e3, 3e4}};
  // A primitive must span many float steps of its position to be a primitive at all.
  std::vector<D3> usable;
  for (const D3& c : p)
    if (scale >= 1e-4 * std::max({std::fabs(c.x), std::fabs(c.y), std::fabs(c.z)})) usable.push_back(c);
  return usable;
}

const double kScales[] = {1e-4, 1e-3, 1e-2, 0.1, 1, 10, 1e2, 1e3, 1e4, 1e5};

TEST(SelfIntersection, RandomTrianglesAtEveryScaleAndPositionAreLitExactly) {
  std::mt19937_64 rng(12345);
  int shapes = 0, rays = 0, wrong = 0;
  uint64_t self_hits = 0;
  std::string first;
  for (double scale : kScales)
    for (const D3& c : positions(rng, scale))
      for (int variant = 0; variant < 8; ++variant) {
        const bool axis = variant % 2 == 0, vertex_at_center = variant >= 6;
        Shape s = random_triangle(rng, c, scale, random_normal(rng, axis), vertex_at_center);
        s.what = describe(axis ? "axis-aligned triangle" : "triangle", c, scale);
        const Outcome o = check_shape(s, rng, 32);
        ++shapes;
        rays += o.rays;
        wrong += o.wrong;
        self_hits += o.self_hits;
        if (first.empty()) first = o.first_wrong;
      }
  EXPECT_GT(shapes, 300);
  EXPECT_EQ(wrong, 0) << wrong << " of " << rays << " rays wrong; first: " << first;
  EXPECT_EQ(self_hits, 0u);
}

TEST(SelfIntersection, RandomSpheresAtEveryScaleAndPositionAreLitExactly) {
  std::mt19937_64 rng(777);
  std::uniform_real_distribution<double> u(-1, 1);
  int rays = 0, wrong = 0;
  uint64_t self_hits = 0;
  std::string first;
  for (double scale : kScales)
    for (const D3& c : positions(rng, scale))
      for (int variant = 0; variant < 3; ++variant) {
        Shape s;
        s.sphere = true;
        s.scale = scale;
        s.radius = float(scale * (0.5 + 0.5 * std::fabs(u(rng))));
        // Centred on c; or touching c (the origin, at c = 0) with its surface.
        D3 centre = c;
        if (variant == 1) centre = c + D3{double(s.radius), 0, 0};
        s.aim_at_origin = variant == 1 && c.x == 0 && c.y == 0 && c.z == 0;
        if (variant == 2) centre = c + random_normal(rng, false) * s.radius;
        s.center = f3(centre);
        s.what = describe("sphere", c, scale);
        const Outcome o = check_shape(s, rng, 32);
        rays += o.rays;
        wrong += o.wrong;
        self_hits += o.self_hits;
        if (first.empty()) first = o.first_wrong;
      }
  EXPECT_GT(rays, 500);
  EXPECT_EQ(wrong, 0) << wrong << " of " << rays << " rays wrong; first: " << first;
  EXPECT_EQ(self_hits, 0u);
}

// The same through an instance: a random object-space triangle placed by a random
// rotation, uneven scale (up to 100:1 between axes, mirrored half the time) and a
// translation to each position, at every scale. Embree intersects in object space and the
// next ray's origin goes there and back (Instance::round_trip_error).
TEST(SelfIntersection, RandomInstancedTrianglesAtEveryScaleAndPositionAreLitExactly) {
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> u(-1, 1);
  int shapes = 0, rays = 0, wrong = 0;
  uint64_t self_hits = 0;
  std::string first;
  for (double scale : kScales)
    for (const D3& c : positions(rng, scale))
      for (int variant = 0; variant < 4; ++variant) {
        // Object space: a triangle about the origin, of size 1 (an axis-aligned plane for
        // even variants), or with a vertex at the origin.
        Shape o = random_triangle(rng, {}, 1, random_normal(rng, variant % 2 == 0), variant == 3);
        const double sx = std::pow(10.0, u(rng)), sy = std::pow(10.0, u(rng)), sz = std::pow(10.0, u(rng));
        const D3 axis = random_normal(rng, false);
        const Mat4 m = Mat4::translate(c.x, c.y, c.z) * Mat4::rotate(axis.x, axis.y, axis.z, 180 * u(rng)) *
                       Mat4::scale(scale * sx * (u(rng) < 0 ? -1 : 1), scale * sy, scale * sz);
        Shape s;
        s.place = m;
        s.scale = scale * std::max({sx, sy, sz});
        for (int k = 0; k < 3; ++k) {
          s.obj[k] = o.v[k];
          s.v[k] = m.point(o.v[k].x, o.v[k].y, o.v[k].z).to_float();
        }
        const D3 e1 = d3(s.v[1]) - d3(s.v[0]), e2 = d3(s.v[2]) - d3(s.v[0]);
        const double longest = std::max({norm(e1), norm(e2), norm(d3(s.v[2]) - d3(s.v[1]))});
        if (norm(cross(e1, e2)) < 0.02 * longest * longest) continue;  // squashed to a sliver
        s.what = describe("instanced triangle", c, scale);
        const Outcome out = check_shape(s, rng, 32);
        ++shapes;
        rays += out.rays;
        wrong += out.wrong;
        self_hits += out.self_hits;
        if (first.empty()) first = out.first_wrong;
      }
  EXPECT_GT(shapes, 100);
  EXPECT_EQ(wrong, 0) << wrong << " of " << rays << " rays wrong; first: " << first;
  EXPECT_EQ(self_hits, 0u);
}

// The triangle of the report: (0,0,0), (1,0,0), (0.5,0.5,0), rendered whole. It was black
// (every shadow ray hit the triangle at t = 0) with 172,064 self-hits.
TEST(SelfIntersection, TheFlatTriangleAtTheOriginIsLit) {
  Shape s;
  s.v[0] = {0, 0, 0};
  s.v[1] = {1, 0, 0};
  s.v[2] = {0.5f, 0.5f, 0};
  s.what = "the reported triangle";
  Scene scene = scene_of(s, {0.5, 0.25, 1}, 1);
  scene.camera.present = true;
  scene.camera.eye = {0.5f, 0.2f, 2};
  scene.camera.xfov_deg = 35;
  scene.camera.aspect_ratio = 1;
  RenderSettings rs;
  rs.camera.framing = Framing::kFile;
  rs.camera.width = rs.camera.height = 32;
  rs.spp = 4;
  const RenderResult r = testing::render(scene, rs);
  EXPECT_EQ(r.stats.rays.self_hits, 0u);
  // The triangle covers about a sixth of the view, and every pixel on it is lit.
  int lit = 0;
  for (const PixelSums& p : r.film.pixels()) lit += p.r > 0;
  EXPECT_GT(lit, 100);
  std::mt19937_64 rng(3);
  const Outcome o = check_shape(s, rng, 200);
  EXPECT_EQ(o.wrong, 0) << o.first_wrong;
}

}  // namespace
}  // namespace tessera
