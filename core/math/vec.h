// Small value types for geometry (Vec3) and colour (Rgb).
//
// Geometry is single precision in the render kernel (Embree works in float); scene loading
// composes transforms in double (transform.h). Points, vectors and normals share Vec3:
// the kernel is small enough that the distinction costs more reading than it saves.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace tessera {

constexpr float kPi = 3.14159265358979323846f;
constexpr float kInvPi = 0.31830988618379067154f;

struct Vec3 {
  float x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

constexpr Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator*(float s, Vec3 a) { return a * s; }
constexpr Vec3 operator/(Vec3 a, float s) { return a * (1.0f / s); }
inline Vec3& operator+=(Vec3& a, Vec3 b) { return a = a + b; }
constexpr bool operator==(Vec3 a, Vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
constexpr float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(Vec3 a, Vec3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
inline float length(Vec3 a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(Vec3 a) { return a / length(a); }
inline Vec3 abs(Vec3 a) { return {std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}; }
inline Vec3 min(Vec3 a, Vec3 b) { return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)}; }
inline Vec3 max(Vec3 a, Vec3 b) { return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)}; }
inline float max_component(Vec3 a) { return std::max(a.x, std::max(a.y, a.z)); }
inline bool is_finite(Vec3 a) { return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z); }
// A vector the same side of the plane with normal n as v.
inline Vec3 face_forward(Vec3 n, Vec3 v) { return dot(n, v) < 0 ? -n : n; }

// Linear RGB radiance or reflectance.
struct Rgb {
  float r = 0, g = 0, b = 0;
  constexpr Rgb() = default;
  constexpr explicit Rgb(float v) : r(v), g(v), b(v) {}
  constexpr Rgb(float r_, float g_, float b_) : r(r_), g(g_), b(b_) {}
  bool is_black() const { return r == 0 && g == 0 && b == 0; }
  float max() const { return std::max(r, std::max(g, b)); }
  // Rec. 709 luminance, the weights the CS184 format document uses.
  float luminance() const { return 0.2126f * r + 0.7152f * g + 0.0722f * b; }
  bool is_finite() const { return std::isfinite(r) && std::isfinite(g) && std::isfinite(b); }
};

constexpr Rgb operator+(Rgb a, Rgb b) { return {a.r + b.r, a.g + b.g, a.b + b.b}; }
constexpr bool operator==(Rgb a, Rgb b) { return a.r == b.r && a.g == b.g && a.b == b.b; }
constexpr Rgb operator-(Rgb a, Rgb b) { return {a.r - b.r, a.g - b.g, a.b - b.b}; }
constexpr Rgb operator*(Rgb a, Rgb b) { return {a.r * b.r, a.g * b.g, a.b * b.b}; }
constexpr Rgb operator*(Rgb a, float s) { return {a.r * s, a.g * s, a.b * s}; }
constexpr Rgb operator*(float s, Rgb a) { return a * s; }
constexpr Rgb operator/(Rgb a, float s) { return a * (1.0f / s); }
inline Rgb& operator+=(Rgb& a, Rgb b) { return a = a + b; }
inline Rgb& operator*=(Rgb& a, Rgb b) { return a = a * b; }
inline Rgb& operator*=(Rgb& a, float s) { return a = a * s; }

struct Vec2 {
  float x = 0, y = 0;
};

// Orthonormal basis around a unit normal (Duff et al. 2017, branchless).
struct Frame {
  Vec3 s, t, n;
  Frame() = default;
  explicit Frame(Vec3 normal) : n(normal) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    s = {1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
    t = {b, sign + n.y * n.y * a, -n.y};
  }
  Vec3 to_local(Vec3 v) const { return {dot(v, s), dot(v, t), dot(v, n)}; }
  Vec3 to_world(Vec3 v) const { return s * v.x + t * v.y + n * v.z; }
};

}  // namespace tessera
