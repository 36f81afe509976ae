#include "core/bsdf/sheen.h"

#include <array>
#include <cmath>

#include "core/math/float_math.h"

namespace tessera {
namespace {

// The fit L(x) of the log of Lambda, interpolated between its alpha = 1 and alpha = 0
// coefficients by (1 - alpha)^2 (the extension's implementation notes).
float charlie_l(float x, float alpha) {
  const float t = (1 - alpha) * (1 - alpha);
  auto mix = [t](float at1, float at0) { return at1 + (at0 - at1) * t; };
  const float a = mix(21.5473f, 25.3245f), b = mix(3.82987f, 3.32435f), c = mix(0.19823f, 0.16801f),
              d = mix(-1.97760f, -1.27393f), e = mix(-4.32054f, -4.85967f);
  return a / (1 + b * fm::pow(x, c)) + d * x + e;
}

float charlie_lambda(float cos_theta, float alpha) {
  const float c = std::fabs(cos_theta);
  return c < 0.5f ? fm::exp(charlie_l(c, alpha)) : fm::exp(2 * charlie_l(0.5f, alpha) - charlie_l(1 - c, alpha));
}

// sheen_f for wo.z, wi.z > 0 with Lambda(wo) and Lambda(wi) given (the albedo table
// computes each once for many pairs; the same bits as computing them here).
float sheen_f_with(float alpha, Vec3 wo, Vec3 wi, float lambda_o, float lambda_i) {
  const Vec3 sum = wo + wi;
  const float len = length(sum);
  if (!(len > 0)) return 0;
  const float g = 1 / (1 + lambda_o + lambda_i);
  return sheen_d(alpha, sum.z / len) * g / (4 * wo.z * wi.z);
}

// E(mu, alpha) on a grid: mu_i = i / (kN - 1), alpha_j = kSheenMinAlpha .. 1.
constexpr int kN = 32;
struct AlbedoTable {
  std::array<float, kN * kN> e{};
  AlbedoTable() {
    // Midpoint rule over (cos theta_i, phi) on a half circle (f is symmetric in phi). The
    // directions, and Lambda at each angle, once: 2 M evaluations of f at first use.
    constexpr int kCos = 64, kPhi = 32;
    std::array<float, kCos> cos_i, sin_i, lambda_i;
    std::array<float, kPhi> cos_phi, sin_phi;
    for (int a = 0; a < kCos; ++a) {
      cos_i[a] = (a + 0.5f) / kCos;
      sin_i[a] = std::sqrt(1 - cos_i[a] * cos_i[a]);
    }
    for (int b = 0; b < kPhi; ++b) {
      const float phi = (b + 0.5f) * kPi / kPhi;
      cos_phi[b] = fm::cos(phi);
      sin_phi[b] = fm::sin(phi);
    }
    for (int j = 0; j < kN; ++j) {
      const float alpha = kSheenMinAlpha + (1 - kSheenMinAlpha) * float(j) / (kN - 1);
      for (int a = 0; a < kCos; ++a) lambda_i[a] = charlie_lambda(cos_i[a], alpha);
      for (int i = 0; i < kN; ++i) {
        const float mu = std::max(float(i) / (kN - 1), 1e-3f);
        const Vec3 wo{std::sqrt(1 - mu * mu), 0, mu};
        const float lambda_o = charlie_lambda(wo.z, alpha);
        double sum = 0;
        for (int a = 0; a < kCos; ++a) {
          const float ci = cos_i[a], si = sin_i[a];
          for (int b = 0; b < kPhi; ++b) {
            const Vec3 wi{si * cos_phi[b], si * sin_phi[b], ci};
            sum += double(sheen_f_with(alpha, wo, wi, lambda_o, lambda_i[a])) * ci;
          }
        }
        e[size_t(j * kN + i)] = float(sum * (1.0 / kCos) * (2 * kPi / kPhi));
      }
    }
  }
};

}  // namespace

float sheen_d(float alpha, float cos_h) {
  const float sin2 = std::max(0.0f, 1 - cos_h * cos_h), inv = 1 / alpha;
  return (2 + inv) * fm::pow(sin2, 0.5f * inv) * (0.5f * kInvPi);
}

float sheen_f(float alpha, Vec3 wo, Vec3 wi) {
  if (wo.z <= 0 || wi.z <= 0) return 0;
  return sheen_f_with(alpha, wo, wi, charlie_lambda(wo.z, alpha), charlie_lambda(wi.z, alpha));
}

float sheen_albedo(float cos_theta, float alpha) {
  static const AlbedoTable table;  // thread-safe, first use only
  // (NaN as 0: clamp passes it through, and int(NaN) indexed far outside the table.)
  const auto unit = [](float v) { return v >= 0 ? std::min(v, 1.0f) : 0.0f; };
  const float x = unit(std::fabs(cos_theta)) * (kN - 1);
  const float y = unit((alpha - kSheenMinAlpha) / (1 - kSheenMinAlpha)) * (kN - 1);
  const int i = std::min(int(x), kN - 2), j = std::min(int(y), kN - 2);
  const float fx = x - float(i), fy = y - float(j);
  auto at = [&](int a, int b) { return table.e[size_t(b * kN + a)]; };
  return (at(i, j) * (1 - fx) + at(i + 1, j) * fx) * (1 - fy) + (at(i, j + 1) * (1 - fx) + at(i + 1, j + 1) * fx) * fy;
}

}  // namespace tessera
