#include "core/scene/deform.h"

#include <array>

namespace tessera {

void apply_morph(const MorphTargets& m, const std::vector<double>& weights, std::vector<Vec3>& p,
                 std::vector<Vec3>& n) {
  for (size_t t = 0; t < m.count() && t < weights.size(); ++t) {
    const float w = float(weights[t]);
    if (w == 0) continue;
    const std::vector<Vec3>& dp = m.positions[t];
    for (size_t i = 0; i < p.size() && i < dp.size(); ++i) p[i] += dp[i] * w;
    const std::vector<Vec3>& dn = m.normals[t];
    for (size_t i = 0; i < n.size() && i < dn.size(); ++i) n[i] += dn[i] * w;
  }
}

void apply_skin(const Skin& s, const std::vector<Mat4>& joint_world, const std::vector<Vec3>& p,
                const std::vector<Vec3>& n, std::vector<Vec3>& out_p, std::vector<Vec3>& out_n) {
  std::vector<Mat4> joint(s.joints.size());
  for (size_t j = 0; j < joint.size(); ++j) joint[j] = joint_world[j] * s.inverse_bind[j];
  out_p.resize(p.size());
  if (!n.empty()) out_n.resize(n.size());
  for (size_t i = 0; i < p.size(); ++i) {
    std::array<double, 16> b{};
    for (uint32_t k = s.first[i]; k < s.first[i + 1]; ++k) {
      const Mat4& m = joint[s.joint[k]];
      const double w = s.weight[k];
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) b[size_t(r * 4 + c)] += w * m(r, c);
    }
    const Mat4 blended = Mat4::from_row_major(b);
    out_p[i] = blended.point(p[i].x, p[i].y, p[i].z).to_float();
    if (i < n.size()) out_n[i] = blended.normal_matrix().unit_vector(n[i].x, n[i].y, n[i].z);
  }
}

}  // namespace tessera
