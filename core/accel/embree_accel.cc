#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/accel/accel.h"
#include "core/math/hash.h"

namespace tessera {

double intersect_sphere(const Vec3& center, float radius, const Ray& ray) {
  // Ray Tracing Gems ch. 7 formulation: the discriminant is computed from the distance
  // of the closest approach, which loses no precision when the ray starts far away.
  const double fx = double(ray.o.x) - center.x, fy = double(ray.o.y) - center.y, fz = double(ray.o.z) - center.z;
  const double dx = ray.d.x, dy = ray.d.y, dz = ray.d.z;
  const double a = dx * dx + dy * dy + dz * dz;
  const double b = -(fx * dx + fy * dy + fz * dz);  // = -dot(f, d)
  const double r2 = double(radius) * radius;
  const double c = fx * fx + fy * fy + fz * fz - r2;
  const double lx = fx + b / a * dx, ly = fy + b / a * dy, lz = fz + b / a * dz;
  const double disc = a * (r2 - (lx * lx + ly * ly + lz * lz));
  if (disc < 0) return -1;
  const double q = b + std::copysign(std::sqrt(disc), b);
  double t0 = q == 0 ? 0 : c / q, t1 = q / a;
  if (t0 > t1) std::swap(t0, t1);
  if (t0 > ray.tmin && t0 <= ray.tmax) return t0;
  if (t1 > ray.tmin && t1 <= ray.tmax) return t1;
  return -1;
}

namespace {

// Embree calls this from C code, where an exception must not pass: record the first error
// and let the constructor throw it after the build.
void error_callback(void* user, RTCError code, const char* str) {
  auto* first = static_cast<std::string*>(user);
  if (first->empty()) *first = "Embree error " + std::to_string(int(code)) + ": " + (str ? str : "");
}

struct SphereData {
  const Scene* scene;
};

void sphere_bounds(const RTCBoundsFunctionArguments* args) {
  const Sphere& s = static_cast<const SphereData*>(args->geometryUserPtr)->scene->spheres[args->primID];
  // Pad by a relative epsilon so float rounding never clips the exact double test.
  const float r = s.radius * (1 + 1e-5f) + 1e-6f * max_component(abs(s.center));
  args->bounds_o->lower_x = s.center.x - r;
  args->bounds_o->lower_y = s.center.y - r;
  args->bounds_o->lower_z = s.center.z - r;
  args->bounds_o->upper_x = s.center.x + r;
  args->bounds_o->upper_y = s.center.y + r;
  args->bounds_o->upper_z = s.center.z + r;
}

void sphere_intersect(const RTCIntersectFunctionNArguments* args) {
  if (!args->valid[0]) return;
  RTCRayHit* rh = reinterpret_cast<RTCRayHit*>(args->rayhit);  // N == 1 (rtcIntersect1)
  const Sphere& s = static_cast<const SphereData*>(args->geometryUserPtr)->scene->spheres[args->primID];
  const Ray ray{{rh->ray.org_x, rh->ray.org_y, rh->ray.org_z},
                {rh->ray.dir_x, rh->ray.dir_y, rh->ray.dir_z},
                rh->ray.tnear,
                rh->ray.tfar};
  const double t = intersect_sphere(s.center, s.radius, Ray{ray.o, ray.d, ray.tmin, ray.tmax});
  if (t < 0 || !(float(t) <= rh->ray.tfar)) return;
  rh->ray.tfar = float(t);
  const Vec3 p = ray.o + ray.d * float(t);
  rh->hit.Ng_x = p.x - s.center.x;
  rh->hit.Ng_y = p.y - s.center.y;
  rh->hit.Ng_z = p.z - s.center.z;
  rh->hit.u = rh->hit.v = 0;
  rh->hit.primID = args->primID;
  rh->hit.geomID = args->geomID;
  rh->hit.instID[0] = args->context->instID[0];
}

void sphere_occluded(const RTCOccludedFunctionNArguments* args) {
  if (!args->valid[0]) return;
  RTCRay* r = reinterpret_cast<RTCRay*>(args->ray);
  const Sphere& s = static_cast<const SphereData*>(args->geometryUserPtr)->scene->spheres[args->primID];
  const Ray ray{{r->org_x, r->org_y, r->org_z}, {r->dir_x, r->dir_y, r->dir_z}, r->tnear, r->tfar};
  if (intersect_sphere(s.center, s.radius, ray) >= 0) r->tfar = -std::numeric_limits<float>::infinity();
}

// A mesh whose material has an alphaMode (Material::AlphaMode): its hits pass through the
// intersection filter, which drops those where the surface is not there.
struct AlphaData {
  const Scene* scene;
  uint32_t mesh;
};

// A uniform number in [0, 1) from the ray and the triangle: the same for a ray's intersect
// and occluded queries and on every machine (its bits only), and independent between
// layers (the triangle is hashed too), so stacked BLEND surfaces are each met with their
// own probability.
float ray_number(const float (&ray_words)[6], uint32_t mesh, uint32_t prim) {
  uint64_t h = mix64((uint64_t(mesh) << 32) | prim);
  for (const float f : ray_words) {
    uint32_t w;
    std::memcpy(&w, &f, sizeof w);
    h = mix64(h ^ (w + 0x9e3779b97f4a7c15ull));
  }
  return float(h >> 40) * 0x1p-24f;
}

// Where the line o + t d meets triangle p0 p1 p2 (Moeller and Trumbore in float, each
// operation rounded once: the same bits on every CPU), its barycentrics kept inside the
// triangle (a grazing hit's may round past an edge). False where the line is parallel to
// the triangle, the triangle degenerate, or a value not finite.
bool triangle_hit(Vec3 p0, Vec3 p1, Vec3 p2, Vec3 o, Vec3 d, float* t, float* u, float* v) {
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const Vec3 pv = cross(d, e2);
  const float det = dot(e1, pv);
  if (!(std::fabs(det) > 0) || !std::isfinite(det)) return false;
  const Vec3 tv = o - p0, qv = cross(tv, e1);
  float a = dot(tv, pv) / det, b = dot(d, qv) / det;
  *t = dot(e2, qv) / det;
  if (!std::isfinite(a) || !std::isfinite(b) || !std::isfinite(*t)) return false;
  a = std::max(a, 0.0f);
  b = std::max(b, 0.0f);
  if (a + b > 1) {
    const float s = a + b;
    a = a / s;
    b = std::min(b / s, 1 - a);
  }
  *u = a;
  *v = b;
  return true;
}

void alpha_filter(const RTCFilterFunctionNArguments* args) {
  for (unsigned i = 0; i < args->N; ++i) {
    if (!args->valid[i]) continue;
    const auto* d = static_cast<const AlphaData*>(args->geometryUserPtr);
    const float words[6] = {RTCRayN_org_x(args->ray, args->N, i), RTCRayN_org_y(args->ray, args->N, i),
                            RTCRayN_org_z(args->ray, args->N, i), RTCRayN_dir_x(args->ray, args->N, i),
                            RTCRayN_dir_y(args->ray, args->N, i), RTCRayN_dir_z(args->ray, args->N, i)};
    const uint32_t prim = RTCHitN_primID(args->hit, args->N, i);
    const float u = ray_number(words, d->mesh, prim);
    // The texel from barycentrics of our own (recompute_triangle_hit says why), in the
    // space Embree hands the ray in (an instance's object space: the mesh's own).
    const Mesh& mesh = d->scene->meshes[d->mesh];
    const uint32_t* idx = &mesh.indices[3 * size_t(prim)];
    float t, b1 = RTCHitN_u(args->hit, args->N, i), b2 = RTCHitN_v(args->hit, args->N, i);
    triangle_hit(mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]],
                 Vec3{words[0], words[1], words[2]}, Vec3{words[3], words[4], words[5]}, &t, &b1, &b2);
    if (!d->scene->covered(mesh, prim, b1, b2, u)) args->valid[i] = 0;
  }
}

RTCRay to_rtc(const Ray& ray) {
  RTCRay r;
  r.org_x = ray.o.x;
  r.org_y = ray.o.y;
  r.org_z = ray.o.z;
  r.dir_x = ray.d.x;
  r.dir_y = ray.d.y;
  r.dir_z = ray.d.z;
  r.tnear = ray.tmin;
  r.tfar = ray.tmax;
  r.time = 0;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
  return r;
}

}  // namespace

namespace {

// A triangle hit's t and barycentrics computed again, by IEEE operations alone (Moeller and
// Trumbore in float, each operation rounded once: -ffp-contract=off), from the triangle
// Embree found. Embree's own come from an approximate reciprocal (rcpps and one Newton
// step) whose last bits differ between Intel's and AMD's CPUs, so the same ray gave another
// hit point on each, and an image depended on the vendor of the CPU that rendered it (on
// an Intel CPU every golden but the one without next-event estimation failed: its sums do
// not depend on where exactly a path lands). Only the choice of triangle is left to Embree;
// the barycentrics are kept inside the triangle (a grazing hit's may round past an edge).
// For an instance's hit the triangle is placed in the world first, as make_surface_point
// places it.
void recompute_triangle_hit(const Scene& scene, const Ray& ray, Hit* hit) {
  const Mesh& m = scene.meshes[hit->shape];
  const uint32_t* idx = &m.indices[3 * size_t(hit->prim)];
  Vec3 p0 = m.positions[idx[0]], p1 = m.positions[idx[1]], p2 = m.positions[idx[2]];
  if (hit->instance >= 0) {
    const Instance& in = scene.instances[size_t(hit->instance)];
    p0 = in.point(p0), p1 = in.point(p1), p2 = in.point(p2);
  }
  float t, u, v;
  if (!triangle_hit(p0, p1, p2, ray.o, ray.d, &t, &u, &v)) return;  // (edge-on or degenerate: Embree's stands)
  hit->t = std::clamp(t, ray.tmin, ray.tmax);  // (Embree found it in the ray's range; ours may round past an end)
  hit->u = u;
  hit->v = v;
}

}  // namespace

struct Accel::Impl {
  const Scene* scene_data = nullptr;  // the scene whose meshes hits name (recompute_triangle_hit)
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  unsigned sphere_geom = RTC_INVALID_GEOMETRY_ID;
  SphereData sphere_data{};
  std::string error;
  bool robust = true;
  bool own_hits = true;                // AccelOptions::own_hits
  std::deque<AlphaData> alpha_data;    // (stable addresses: Embree keeps pointers)
  std::shared_ptr<const Accel> fixed;  // a pose's static part (its device is this one's)
  unsigned fixed_sphere_geom = RTC_INVALID_GEOMETRY_ID;
  // Instanced meshes: one scene each (null for others), placed by instance geometries
  // whose ids start at instance_base.
  std::vector<RTCScene> prototypes;
  unsigned instance_base = RTC_INVALID_GEOMETRY_ID;
  ~Impl() {
    for (RTCScene p : prototypes)
      if (p) rtcReleaseScene(p);
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
  void new_scene(RTCDevice d) {
    device = d;
    rtcRetainDevice(device);
    rtcSetDeviceErrorFunction(device, error_callback, &error);
    scene = new_rtc_scene();
  }
  RTCScene new_rtc_scene() const {
    RTCScene sc = rtcNewScene(device);
    // ROBUST: watertight triangle tests, so rays along shared edges never leak.
    rtcSetSceneFlags(sc, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    rtcSetSceneBuildQuality(sc, RTC_BUILD_QUALITY_HIGH);
    return sc;
  }
  // Each instanced mesh in a scene of its own (geomID still the mesh index), committed, and
  // one instance geometry per Scene::instances entry.
  void add_instances(const Scene& s) {
    if (s.instances.empty()) return;
    prototypes.assign(s.meshes.size(), nullptr);
    instance_base = unsigned(s.meshes.size() + 2);  // after the spheres and a pose's static part
    for (size_t k = 0; k < s.instances.size(); ++k) {
      const Instance& in = s.instances[k];
      RTCScene& proto = prototypes[in.mesh];
      if (!proto) {
        proto = new_rtc_scene();
        add_mesh(s, in.mesh, proto);
        rtcCommitScene(proto);
      }
      RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
      rtcSetGeometryInstancedScene(g, proto);
      rtcSetGeometryTimeStepCount(g, 1);
      rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, in.to_world.data());
      rtcCommitGeometry(g);
      rtcAttachGeometryByID(scene, g, instance_base + unsigned(k));
      rtcReleaseGeometry(g);
    }
  }
  void add_mesh(const Scene& s, unsigned id) { add_mesh(s, id, scene); }
  void add_mesh(const Scene& s, unsigned id, RTCScene target) {
    const Mesh& m = s.meshes[id];
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree may read 16 bytes from the last vertex: pad by one.
    float* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), m.positions.size() + 1));
    for (size_t k = 0; k < m.positions.size(); ++k) {
      v[3 * k] = m.positions[k].x;
      v[3 * k + 1] = m.positions[k].y;
      v[3 * k + 2] = m.positions[k].z;
    }
    v[3 * m.positions.size()] = v[3 * m.positions.size() + 1] = v[3 * m.positions.size() + 2] = 0;
    uint32_t* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                   3 * sizeof(uint32_t), m.triangle_count()));
    std::copy(m.indices.begin(), m.indices.end(), idx);
    if (s.materials[m.material].alpha_mode != Material::AlphaMode::kOpaque) {  // only these pay for a filter
      alpha_data.push_back({&s, id});
      rtcSetGeometryUserData(g, &alpha_data.back());
      rtcSetGeometryIntersectFilterFunction(g, alpha_filter);
      rtcSetGeometryOccludedFilterFunction(g, alpha_filter);
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(target, g, id);  // geomID == mesh index
    rtcReleaseGeometry(g);
  }
  void add_spheres(const Scene& s) {
    if (s.spheres.empty()) return;
    sphere_data.scene = &s;
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, unsigned(s.spheres.size()));
    rtcSetGeometryUserData(g, &sphere_data);
    rtcSetGeometryBoundsFunction(g, sphere_bounds, nullptr);
    rtcSetGeometryIntersectFunction(g, sphere_intersect);
    rtcSetGeometryOccludedFunction(g, sphere_occluded);
    rtcCommitGeometry(g);
    sphere_geom = unsigned(s.meshes.size());
    rtcAttachGeometryByID(scene, g, sphere_geom);
    rtcReleaseGeometry(g);
  }
  void commit() {
    rtcCommitScene(scene);
    if (!error.empty()) throw std::runtime_error(error);
  }
};

namespace {
RTCDevice new_device(const AccelOptions& options) {
  const std::string config = std::string("max_isa=") + options.max_isa;
  RTCDevice d = rtcNewDevice(config.c_str());
  if (!d)
    throw std::runtime_error("cannot create Embree device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) +
                             ")");
  return d;
}
}  // namespace

Accel::Accel(const Scene& scene, AccelOptions options) : Accel(scene, std::vector<bool>(), options) {}

Accel::Accel(const Scene& scene, const std::vector<bool>& skip, AccelOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->scene_data = &scene;
  impl_->robust = options.robust;
  impl_->own_hits = options.own_hits;
  RTCDevice d = new_device(options);
  impl_->new_scene(d);
  rtcReleaseDevice(d);  // the Impl holds it
  for (size_t i = 0; i < scene.meshes.size(); ++i)
    if (!scene.meshes[i].instanced && (i >= skip.size() || !skip[i])) impl_->add_mesh(scene, unsigned(i));
  impl_->add_spheres(scene);
  impl_->add_instances(scene);
  impl_->commit();
}

Accel::Accel(const Scene& scene, std::shared_ptr<const Accel> fixed, const std::vector<bool>& moving)
    : impl_(std::make_unique<Impl>()) {
  if (!scene.instances.empty())  // (the loaders copy instances in animated scenes)
    throw std::logic_error("an animated scene's pose cannot hold instanced meshes");
  impl_->scene_data = &scene;              // (its static meshes are the fixed part's, where they were)
  impl_->new_scene(fixed->impl_->device);  // an instance must live on its scene's device
  impl_->fixed = fixed;
  impl_->fixed_sphere_geom = fixed->impl_->sphere_geom;
  for (size_t i = 0; i < scene.meshes.size() && i < moving.size(); ++i)
    if (moving[i]) impl_->add_mesh(scene, unsigned(i));
  RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(g, fixed->impl_->scene);
  rtcSetGeometryTimeStepCount(g, 1);
  const float identity[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};  // 3x4, column-major
  rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, identity);
  rtcCommitGeometry(g);
  rtcAttachGeometryByID(impl_->scene, g, unsigned(scene.meshes.size() + 1));
  rtcReleaseGeometry(g);
  impl_->commit();
}

Accel::~Accel() = default;

bool Accel::intersect(const Ray& ray, Hit* hit) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray = to_rtc(ray);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  hit->t = rh.ray.tfar;
  hit->u = rh.hit.u;
  hit->v = rh.hit.v;
  hit->ng = {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
  // A hit inside a pose's static part reports that part's geometry ids (mesh indices too).
  hit->is_sphere =
      rh.hit.geomID == (rh.hit.instID[0] == RTC_INVALID_GEOMETRY_ID ? impl_->sphere_geom : impl_->fixed_sphere_geom);
  hit->shape = hit->is_sphere ? rh.hit.primID : rh.hit.geomID;
  hit->prim = rh.hit.primID;
  hit->instance = rh.hit.instID[0] != RTC_INVALID_GEOMETRY_ID && rh.hit.instID[0] >= impl_->instance_base
                      ? int32_t(rh.hit.instID[0] - impl_->instance_base)
                      : -1;
  if (!hit->is_sphere && impl_->own_hits) recompute_triangle_hit(*impl_->scene_data, ray, hit);
  return true;
}

bool Accel::occluded(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r = to_rtc(ray);
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar < 0;
}

}  // namespace tessera
