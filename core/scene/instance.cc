#include "core/scene/instance.h"

#include <cmath>
#include <limits>

namespace tessera {
namespace {

Vec3 apply34(const std::array<float, 12>& m, Vec3 p, double w) {
  const double x = p.x, y = p.y, z = p.z;
  return {float(m[0] * x + m[1] * y + m[2] * z + m[3] * w), float(m[4] * x + m[5] * y + m[6] * z + m[7] * w),
          float(m[8] * x + m[9] * y + m[10] * z + m[11] * w)};
}

}  // namespace

std::optional<Instance> Instance::make(uint32_t mesh, const Mat4& m) {
  const double det = m.det3();
  if (!std::isfinite(det) || std::fabs(det) < 1e-30) return std::nullopt;
  Instance in;
  in.mesh = mesh;
  in.mirrored = det < 0;
  const Mat4 cof = m.normal_matrix();  // cofactors: det x the inverse transpose
  double inv[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      inv[r][c] = cof(c, r) / det;
      in.normal[size_t(r * 3 + c)] = float(cof(r, c) / det);
    }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) in.to_world[size_t(r * 4 + c)] = float(m(r, c));
    double t = 0;  // -inv x translation
    for (int c = 0; c < 3; ++c) {
      in.to_object[size_t(r * 4 + c)] = float(inv[r][c]);
      t -= inv[r][c] * m(c, 3);
    }
    in.to_object[size_t(r * 4 + 3)] = float(t);
  }
  for (float f : in.to_world)
    if (!std::isfinite(f)) return std::nullopt;
  // Embree takes each ray into object space and asserts (aborting the process) on one past
  // about 1.8e18: an axis scaled below 1e-5 (inverse entries past 1e5, origins within 1e12)
  // could send one there. Such a mesh is copied into world space instead.
  for (const double* row : inv)
    for (int c = 0; c < 3; ++c)
      if (!(std::fabs(row[c]) <= kMaxInverse)) return std::nullopt;
  for (float f : in.to_object)
    if (!std::isfinite(f) || !(std::fabs(f) <= float(kMaxInverse * 1e12)))
      return std::nullopt;  // (1e12: kMaxCoordinate)
  return in;
}

Vec3 Instance::point(Vec3 p) const { return apply34(to_world, p, 1); }
Vec3 Instance::vector(Vec3 v) const { return apply34(to_world, v, 0); }

Vec3 Instance::normal_to_world(Vec3 n) const {
  const double x = n.x, y = n.y, z = n.z;
  return {float(normal[0] * x + normal[1] * y + normal[2] * z), float(normal[3] * x + normal[4] * y + normal[5] * z),
          float(normal[6] * x + normal[7] * y + normal[8] * z)};
}

Vec3 Instance::abs_vector(Vec3 v) const {
  const std::array<float, 12>& m = to_world;
  return {std::fabs(m[0]) * v.x + std::fabs(m[1]) * v.y + std::fabs(m[2]) * v.z,
          std::fabs(m[4]) * v.x + std::fabs(m[5]) * v.y + std::fabs(m[6]) * v.z,
          std::fabs(m[8]) * v.x + std::fabs(m[9]) * v.y + std::fabs(m[10]) * v.z};
}

Vec3 Instance::round_trip_error(Vec3 p) const {
  // Embree's own inverse (float, a few roundings per entry) and its float transform of the
  // origin each err by a small multiple of eps times |inverse| (|p| + |t|); taken back to
  // the world by |to_world|. 16 eps covers both with a wide margin.
  constexpr float kEps = std::numeric_limits<float>::epsilon() * 0.5f;
  constexpr float kGamma = 16 * kEps / (1 - 16 * kEps);
  const std::array<float, 12>& m = to_object;
  const Vec3 a = abs(p);
  const Vec3 obj{std::fabs(m[0]) * a.x + std::fabs(m[1]) * a.y + std::fabs(m[2]) * a.z + std::fabs(m[3]),
                 std::fabs(m[4]) * a.x + std::fabs(m[5]) * a.y + std::fabs(m[6]) * a.z + std::fabs(m[7]),
                 std::fabs(m[8]) * a.x + std::fabs(m[9]) * a.y + std::fabs(m[10]) * a.z + std::fabs(m[11])};
  return abs_vector(obj) * kGamma;
}

}  // namespace tessera
