// 4x4 affine transforms in double precision, used while loading scenes.
//
// COLLADA node matrices are composed in double so that a scene far from the origin or at an
// extreme scale loses nothing before its vertices are stored as float.
#pragma once

#include <array>
#include <cmath>

#include "core/math/vec.h"

namespace tessera {

struct Dvec3 {
  double x = 0, y = 0, z = 0;
  Vec3 to_float() const { return {float(x), float(y), float(z)}; }
};

inline Dvec3 operator-(Dvec3 a, Dvec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline double dlength(Dvec3 a) { return std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z); }
inline Dvec3 dcross(Dvec3 a, Dvec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
// v made unit length: normalize(v.to_float()) where float holds its squared length well
// (the bits every scene had); in double where it may not (a length past about 1e19
// overflows the square, making the result zero; under about 1e-19 it underflows, making it
// NaN or inexact). Zero if v is zero or not finite.
inline Vec3 unit(Dvec3 v) {
  const Vec3 f = v.to_float();
  const float len = length(f);
  if (len > 1e-18f && len < 1e18f) return normalize(f);
  const double d = dlength(v);
  if (!(d > 0) || !std::isfinite(d)) return {};
  return Dvec3{v.x / d, v.y / d, v.z / d}.to_float();
}

class Mat4 {
 public:
  Mat4() {
    for (int i = 0; i < 4; ++i) m_[i][i] = 1;
  }
  // Row-major: m[row][col]; column vectors; the last column is the translation.
  static Mat4 from_row_major(const std::array<double, 16>& v) {
    Mat4 r;
    for (int i = 0; i < 16; ++i) r.m_[i / 4][i % 4] = v[i];
    return r;
  }
  static Mat4 translate(double x, double y, double z) {
    Mat4 r;
    r.m_[0][3] = x;
    r.m_[1][3] = y;
    r.m_[2][3] = z;
    return r;
  }
  static Mat4 scale(double x, double y, double z) {
    Mat4 r;
    r.m_[0][0] = x;
    r.m_[1][1] = y;
    r.m_[2][2] = z;
    return r;
  }
  // Rotation by `degrees` about the axis (x, y, z) (Rodrigues), as COLLADA's <rotate>.
  static Mat4 rotate(double x, double y, double z, double degrees) {
    const double len = std::sqrt(x * x + y * y + z * z);
    Mat4 r;
    if (len == 0) return r;
    x /= len;
    y /= len;
    z /= len;
    const double a = degrees * M_PI / 180.0, c = std::cos(a), s = std::sin(a), t = 1 - c;
    r.m_[0][0] = t * x * x + c;
    r.m_[0][1] = t * x * y - s * z;
    r.m_[0][2] = t * x * z + s * y;
    r.m_[1][0] = t * x * y + s * z;
    r.m_[1][1] = t * y * y + c;
    r.m_[1][2] = t * y * z - s * x;
    r.m_[2][0] = t * x * z - s * y;
    r.m_[2][1] = t * y * z + s * x;
    r.m_[2][2] = t * z * z + c;
    return r;
  }
  Mat4 operator*(const Mat4& o) const {
    Mat4 r;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        double s = 0;
        for (int k = 0; k < 4; ++k) s += m_[i][k] * o.m_[k][j];
        r.m_[i][j] = s;
      }
    return r;
  }
  // Applies to (x, y, z, w) and returns xyz (no divide).
  Dvec3 apply(double x, double y, double z, double w) const {
    return {m_[0][0] * x + m_[0][1] * y + m_[0][2] * z + m_[0][3] * w,
            m_[1][0] * x + m_[1][1] * y + m_[1][2] * z + m_[1][3] * w,
            m_[2][0] * x + m_[2][1] * y + m_[2][2] * z + m_[2][3] * w};
  }
  // Point with homogeneous divide.
  Dvec3 point(double x, double y, double z) const {
    Dvec3 p = apply(x, y, z, 1);
    const double w = m_[3][0] * x + m_[3][1] * y + m_[3][2] * z + m_[3][3];
    if (w != 1 && w != 0) {
      p.x /= w;
      p.y /= w;
      p.z /= w;
    }
    return p;
  }
  Dvec3 vector(double x, double y, double z) const { return apply(x, y, z, 0); }
  double operator()(int r, int c) const { return m_[r][c]; }
  // Determinant of the upper 3x3: negative for a transform that mirrors.
  double det3() const {
    return m_[0][0] * (m_[1][1] * m_[2][2] - m_[1][2] * m_[2][1]) -
           m_[0][1] * (m_[1][0] * m_[2][2] - m_[1][2] * m_[2][0]) +
           m_[0][2] * (m_[1][0] * m_[2][1] - m_[1][1] * m_[2][0]);
  }
  // For normals: the inverse transpose of the upper 3x3, as its cofactor matrix (same
  // direction, no divide); normalize what it gives (unit_vector).
  Mat4 normal_matrix() const {
    std::array<double, 16> c{};
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) {
        const int r1 = (r + 1) % 3, r2 = (r + 2) % 3, k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        c[size_t(r * 4 + k)] = m_[r1][k1] * m_[r2][k2] - m_[r1][k2] * m_[r2][k1];
      }
    c[15] = 1;
    return from_row_major(c);
  }
  // The direction (x, y, z) transformed, unit length; zero where the transform degenerates.
  Vec3 unit_vector(double x, double y, double z) const {
    const Vec3 v = vector(x, y, z).to_float();
    const float len = length(v);
    return len > 0 && std::isfinite(len) ? v / len : Vec3{};
  }

 private:
  double m_[4][4] = {};
};

}  // namespace tessera
