// Real instances (Scene::instances, glTF EXT_mesh_gpu_instancing): a mesh stored once and
// placed many times renders as its world-space copies do, mirrored placements included;
// an instanced lamp becomes copies that light the scene; memory is the one mesh.
#include <gtest/gtest.h>

#include <cmath>

#include "core/accel/accel.h"
#include "core/scene/scene_error.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

// A unit quad of two triangles in its object space (z = 0, facing +z), grey, glowing a
// little from its front (one-sided: a mirrored placement that showed its back would be dark).
Mesh quad(uint32_t material) {
  Mesh m;
  m.name = "quad";
  m.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.material = material;
  return m;
}

// Placements: turned, scaled unevenly, mirrored in x, far off-centre.
std::vector<Mat4> placements() {
  return {Mat4::translate(-2.5, 0, 0) * Mat4::rotate(0, 1, 0, 30),
          Mat4::translate(0, 1, -1) * Mat4::rotate(1, 0, 0, -20) * Mat4::scale(0.5, 1.5, 1),
          Mat4::translate(2.5, 0, 0) * Mat4::scale(-1, 1, 1) * Mat4::rotate(0, 1, 0, -30),
          Mat4::translate(0, -1.8, 0.5) * Mat4::rotate(1, 0, 0, -80) * Mat4::scale(4, 2, 1)};
}

// The quad at every placement: as instances, or as world-space copies (what the loader
// made before, and still makes for animated files).
Scene quads(bool instanced) {
  Scene s;
  Material m = testing::pbr_material(0, 0.5f);
  m.reflectance = Rgb(0.6f, 0.5f, 0.4f);
  m.radiance = Rgb(0.3f, 0.1f, 0.05f);
  m.two_sided_emission = false;
  s.materials.push_back(m);
  const Mesh q = quad(0);
  if (instanced) {
    s.meshes.push_back(q);
    s.meshes[0].instanced = true;
    for (const Mat4& p : placements()) s.instances.push_back(*Instance::make(0, p));
  } else {
    for (const Mat4& p : placements()) {
      Mesh c = q;
      for (Vec3& v : c.positions) v = p.point(v.x, v.y, v.z).to_float();
      if (p.det3() < 0)
        for (size_t t = 0; t < c.indices.size(); t += 3) std::swap(c.indices[t + 1], c.indices[t + 2]);
      s.meshes.push_back(c);
    }
  }
  Light sun;
  sun.kind = Light::Kind::kDirectional;
  sun.direction = normalize(Vec3{0.3f, 0.5f, 1});
  sun.color = Rgb(2);
  s.lights.push_back(sun);
  s.camera.present = true;
  s.camera.eye = {0, 0.5f, 7};
  s.camera.xfov_deg = 70;
  s.camera.aspect_ratio = 1.5;
  s.finalize();
  return s;
}

RenderSettings settings() {
  RenderSettings rs;
  rs.camera.framing = Framing::kFile;
  rs.camera.width = 96;
  rs.camera.height = 64;
  rs.spp = 8;
  rs.max_depth = 4;
  rs.environment = Rgb(0.2f);
  return rs;
}

TEST(Instances, RenderAsTheirWorldSpaceCopies) {
  const Scene inst = quads(true), copies = quads(false);
  ASSERT_EQ(inst.meshes.size(), 1u);
  ASSERT_EQ(inst.instances.size(), 4u);
  EXPECT_TRUE(inst.instances[2].mirrored);
  EXPECT_EQ(inst.triangle_count(), copies.triangle_count());
  const Bounds a = inst.object_bounds(), b = copies.object_bounds();
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(a.lo[k], b.lo[k], 1e-5f);
    EXPECT_NEAR(a.hi[k], b.hi[k], 1e-5f);
  }
  const RenderResult x = testing::render(inst, settings()), y = testing::render(copies, settings());
  EXPECT_EQ(x.stats.rays.self_hits, 0u);
  EXPECT_EQ(y.stats.rays.self_hits, 0u);
  // The same sample sequences over the same surfaces: hit points differ in the last bits
  // (Embree intersects in object space), so paths agree but for rare grazing ones.
  size_t differ = 0, covered = 0;
  double sx = 0, sy = 0;
  for (size_t i = 0; i < x.film.pixels().size(); ++i) {
    const PixelSums &p = x.film.pixels()[i], &q = y.film.pixels()[i];
    sx += p.lum_sum();
    sy += q.lum_sum();
    covered += std::fabs(p.lum_sum() - 0.2 * p.n) > 1e-4 * p.n;  // not the bare environment
    if (std::fabs(p.lum_sum() - q.lum_sum()) > 1e-3 * std::max(1.0, q.lum_sum())) ++differ;
  }
  EXPECT_GT(covered, x.film.pixels().size() / 5);  // the quads fill a good part of the frame
  EXPECT_LT(differ, x.film.pixels().size() / 100) << differ << " pixels differ";
  EXPECT_NEAR(sx / sy, 1.0, 2e-3);
}

TEST(Instances, AnInstancedLampBecomesCopiesThatLightTheScene) {
  Scene s;
  Material lamp = testing::pbr_material(0, 1);
  lamp.radiance = Rgb(5);  // over Scene::kLampRadiance: sampled as a light
  s.materials.push_back(lamp);
  s.meshes.push_back(quad(0));
  s.meshes[0].instanced = true;
  for (const Mat4& p : placements()) s.instances.push_back(*Instance::make(0, p));
  s.finalize();
  EXPECT_TRUE(s.instances.empty());
  ASSERT_EQ(s.meshes.size(), 4u);
  ASSERT_EQ(s.lights.size(), 4u);
  for (const Mesh& m : s.meshes) {
    EXPECT_FALSE(m.instanced);
    EXPECT_GE(m.light, 0);
  }
  // The mirrored copy keeps its authored front: its winding's normal is the placed +z.
  const Mesh& m = s.meshes[2];
  const Vec3 n = cross(m.positions[m.indices[1]] - m.positions[m.indices[0]],
                       m.positions[m.indices[2]] - m.positions[m.indices[0]]);
  const Vec3 front = Instance::make(0, placements()[2])->normal_to_world({0, 0, 1});
  EXPECT_GT(dot(n, front), 0);
}

TEST(Instances, PlacementsBeyondTheRayTracersRangeAreRefusedByName) {
  Scene s = quads(false);
  s.meshes.push_back(quad(0));
  s.meshes.back().instanced = true;
  s.instances.push_back(*Instance::make(uint32_t(s.meshes.size() - 1), Mat4::translate(5e12, 0, 0)));
  try {
    s.finalize();
    FAIL() << "accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("mesh 'quad' instance 0"), std::string::npos) << e.what();
  }
}

// Many placements of one mesh cost the mesh once: 2,000 instances of a 20,000-triangle grid
// (40 M triangles as rendered) keep 20,000 stored, and render.
TEST(Instances, ThousandsOfPlacementsStoreTheMeshOnce) {
  Scene s;
  s.materials.push_back(testing::pbr_material(0, 0.5f));
  s.materials[0].reflectance = Rgb(0.3f);  // (white would reflect the environment back as it is)
  Mesh grid;
  grid.name = "grid";
  const int n = 100;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) grid.positions.push_back({float(i) / n, float(j) / n, 0.1f * float((i + j) % 2)});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = uint32_t(j * (n + 1) + i), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
      grid.indices.insert(grid.indices.end(), {a, b, d, a, d, c});
    }
  grid.instanced = true;
  s.meshes.push_back(grid);
  for (int k = 0; k < 2000; ++k)
    s.instances.push_back(
        *Instance::make(0, Mat4::translate(k % 50 * 1.1, k / 50 * 1.1, -0.01 * k) * Mat4::rotate(0, 0, 1, k)));
  s.camera.present = true;
  s.camera.eye = {27, 22, 35};
  s.camera.xfov_deg = 60;
  s.camera.aspect_ratio = 1;
  s.finalize();
  EXPECT_EQ(s.triangle_count(), 40'000'000u);
  EXPECT_EQ(s.meshes[0].triangle_count(), 20'000u);
  RenderSettings rs = settings();
  rs.camera.width = rs.camera.height = 32;
  rs.spp = 1;
  const RenderResult r = testing::render(s, rs);
  EXPECT_EQ(r.stats.rays.self_hits, 0u);
  size_t hit = 0;
  for (const PixelSums& p : r.film.pixels()) hit += std::fabs(p.lum_sum() - 0.2 * p.n) > 1e-4 * p.n;
  EXPECT_GT(hit, r.film.pixels().size() / 2);
}

}  // namespace
}  // namespace tessera
