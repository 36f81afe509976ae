// Chi-square goodness-of-fit test for direction sampling routines (as Mitsuba and pbrt
// test theirs): histogram N sampled directions over (cos theta, phi) cells, integrate the
// claimed pdf over each cell numerically, pool cells whose expectation is below 5, and
// reject when the p-value falls below the significance level.
#pragma once

#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/math/vec.h"

namespace tessera::testing {

// Regularised upper incomplete gamma Q(a, x) (Numerical Recipes 6.2).
inline double gamma_q(double a, double x) {
  if (x <= 0) return 1;
  const double gln = std::lgamma(a);
  if (x < a + 1) {  // series for P
    double ap = a, sum = 1 / a, del = sum;
    for (int n = 0; n < 10000; ++n) {
      ap += 1;
      del *= x / ap;
      sum += del;
      if (std::fabs(del) < std::fabs(sum) * 1e-15) break;
    }
    return 1 - sum * std::exp(-x + a * std::log(x) - gln);
  }
  double b = x + 1 - a, c = 1e300, d = 1 / b, h = d;  // continued fraction for Q
  for (int i = 1; i < 10000; ++i) {
    const double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::fabs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::fabs(c) < 1e-300) c = 1e-300;
    d = 1 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1) < 1e-15) break;
  }
  return std::exp(-x + a * std::log(x) - gln) * h;
}

struct Chi2Result {
  double statistic = 0, p_value = 1;
  int dof = 0;
  std::string describe() const {
    return "chi2=" + std::to_string(statistic) + " dof=" + std::to_string(dof) + " p=" + std::to_string(p_value);
  }
};

// sample(i) returns a unit direction or nullopt (a failed sample, which the pdf's missing
// mass must account for). pdf(w) is the claimed solid-angle density.
inline Chi2Result chi2_directions(const std::function<std::optional<Vec3>(int)>& sample,
                                  const std::function<double(Vec3)>& pdf, int n_samples, int theta_bins = 20,
                                  int phi_bins = 40, int sub = 8) {
  const int cells = theta_bins * phi_bins;
  std::vector<double> observed(cells + 1, 0), expected(cells + 1, 0);
  auto cell_of = [&](Vec3 w) {
    const double z = std::clamp(double(w.z), -1.0, 1.0);
    int t = std::min(theta_bins - 1, int((z + 1) / 2 * theta_bins));
    double phi = std::atan2(double(w.y), double(w.x));
    if (phi < 0) phi += 2 * M_PI;
    int p = std::min(phi_bins - 1, int(phi / (2 * M_PI) * phi_bins));
    return t * phi_bins + p;
  };
  for (int i = 0; i < n_samples; ++i) {
    const auto w = sample(i);
    observed[w ? cell_of(*w) : cells] += 1;
  }
  // Integrate the pdf over each cell (sub x sub midpoint rule; a pdf with edges, such as
  // an area light's, needs a finer rule). Uniform in z and phi is uniform in solid angle.
  double total = 0;
  for (int t = 0; t < theta_bins; ++t)
    for (int p = 0; p < phi_bins; ++p) {
      double acc = 0;
      for (int a = 0; a < sub; ++a)
        for (int b = 0; b < sub; ++b) {
          const double z = -1 + 2.0 * (t + (a + 0.5) / sub) / theta_bins;
          const double phi = 2 * M_PI * (p + (b + 0.5) / sub) / phi_bins;
          const double r = std::sqrt(std::max(0.0, 1 - z * z));
          acc += pdf(Vec3{float(r * std::cos(phi)), float(r * std::sin(phi)), float(z)});
        }
      const double cell_area = 4 * M_PI / cells;
      expected[t * phi_bins + p] = acc / (sub * sub) * cell_area * n_samples;
      total += expected[t * phi_bins + p];
    }
  expected[cells] = std::max(0.0, n_samples - total);  // failed samples
  // Pool small cells.
  Chi2Result r;
  double pool_o = 0, pool_e = 0;
  int used = 0;
  for (int i = 0; i <= cells; ++i) {
    if (expected[i] < 5) {
      pool_o += observed[i];
      pool_e += expected[i];
      continue;
    }
    r.statistic += (observed[i] - expected[i]) * (observed[i] - expected[i]) / expected[i];
    ++used;
  }
  if (pool_e >= 5) {
    r.statistic += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
    ++used;
  } else if (pool_o > 20 + 10 * pool_e) {
    r.statistic += 1e9;  // mass where the pdf claims there is none
  }
  r.dof = std::max(1, used - 1);
  r.p_value = gamma_q(r.dof / 2.0, r.statistic / 2.0);
  return r;
}

}  // namespace tessera::testing
