// Where a light path must go first: the light tracer (light_tracer.h) keeps only paths
// whose first hit scatters by a delta lobe, so it aims light paths' first directions at
// bounding spheres of the scene's mirror and glass shapes (photon mapping's "projection
// maps", Jensen 2001) instead of spending a ray on every direction a light emits in. The
// spheres bound every delta-lobe surface, so every direction that can reach one keeps a
// density above zero and the estimate stays unbiased.
#pragma once

#include <cstdint>
#include <vector>

#include "core/math/vec.h"
#include "core/scene/scene.h"

namespace tessera {

// Whether material m can scatter by a delta lobe: a mirror, glass, or a glTF material
// smooth enough (Material::kSmoothAlpha; textured roughness taken at its factor). A
// texture can make a surface delta where this says no (roughness factor 1, a texel of
// 0): such a surface is not a target, and the light tracer and the path tracer both
// leave its paths to the path tracer (DeltaTargets::aims_at), so nothing is lost.
bool has_delta_lobe(const Material& m);

class DeltaTargets {
 public:
  struct Target {
    Vec3 center;
    float radius = 0;
  };
  // More than this many shapes are bounded by one sphere around them all (the density is
  // a sum over targets, evaluated once a light path).
  static constexpr size_t kMaxTargets = 64;

  explicit DeltaTargets(const Scene& scene);
  const std::vector<Target>& targets() const { return targets_; }
  // Per material (Scene::materials): whether its shapes are targets. A light path counts
  // only where its first hit is on one, and the path tracer leaves to it only the paths
  // whose last scattering before the light is on one: the same paths on both sides.
  const std::vector<uint8_t>& target_materials() const { return materials_; }
  bool aims_at(uint32_t material) const { return material < materials_.size() && materials_[material]; }
  bool empty() const { return targets_.empty(); }

  // A unit direction from p: a target picked uniformly by u_pick, then uniform in the cone
  // it subtends from p (the whole sphere of directions from inside it; without targets,
  // uniform over the sphere). *pdf: the solid-angle density of the whole mixture there.
  Vec3 sample(Vec3 p, float u_pick, Vec2 u, float* pdf) const;
  // That density for direction dir from p (0 where no cone holds it).
  float pdf(Vec3 p, Vec3 dir) const { return pdf_with(p, dir, SIZE_MAX); }

 private:
  // The density, counting target `sure` as holding dir whatever rounding says.
  float pdf_with(Vec3 p, Vec3 dir, size_t sure) const;
  std::vector<Target> targets_;
  std::vector<uint8_t> materials_;
};

}  // namespace tessera
