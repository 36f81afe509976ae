// A placement of a mesh without a copy of its triangles (glTF EXT_mesh_gpu_instancing).
// The mesh (Mesh::instanced) holds its geometry once, in its own object space; each
// Instance maps it into the world with an affine transform. Embree traces the mesh's one
// BVH through every instance (core/accel); make_surface_point takes a hit back into world
// space, with error bounds that cover the transforms (docs/ray-offsets.md).
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "core/math/transform.h"
#include "core/math/vec.h"

namespace tessera {

struct Instance {
  uint32_t mesh = 0;
  // Object to world, 3x4 row-major (the last column translates), and its inverse, both
  // computed in double and rounded once. Embree is given `to_world` and inverts it itself.
  std::array<float, 12> to_world{}, to_object{};
  // The inverse transpose of to_world's 3x3 (normals into world space), row-major.
  std::array<float, 9> normal{};
  // det < 0: the transform mirrors, so the authored front face winds the other way.
  bool mirrored = false;

  // `m` as an instance of mesh `mesh`; nothing where m is singular or not finite (a
  // placement scaled to nothing has no surface to render), or its inverse has an entry past
  // kMaxInverse (an axis scaled below 1e-5: Embree's object-space rays could pass its range).
  static constexpr double kMaxInverse = 1e5;
  static std::optional<Instance> make(uint32_t mesh, const Mat4& m);

  // Each is computed in double and rounded once.
  Vec3 point(Vec3 p) const;   // object to world
  Vec3 vector(Vec3 v) const;  // a direction or an edge, object to world
  Vec3 normal_to_world(Vec3 n) const;
  // Error bounds: |to_world| x v (componentwise absolute values), and the world-space bound
  // on where a ray leaving world point p lands after Embree takes its origin into object
  // space (float, with its own float inverse) and back.
  Vec3 abs_vector(Vec3 v) const;
  Vec3 round_trip_error(Vec3 p) const;
};

}  // namespace tessera
