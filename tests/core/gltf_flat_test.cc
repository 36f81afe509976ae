// glTF's flat shading: a primitive without NORMAL shades with its triangles' own normals
// (needs the kernel's surface point, so it is a core test).
#include <gtest/gtest.h>

#include "core/render/integrator.h"
#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

// Found by audit: a primitive without NORMAL was shaded with area-weighted vertex normals,
// smooth across its edges (a cube read 6% dark at its faces' edges under a light head on;
// it failed the white furnace). The spec: "client implementations MUST calculate flat
// normals and the provided tangents (if present) MUST be ignored" (3.7.2.1). Two triangles
// folded along a shared edge: each shades with its own normal.
TEST_F(Gltf, APrimitiveWithoutNormalsIsFlatShadedAndItsTangentsIgnored) {
  Doc d;
  d.blob.clear();
  put<float>(d.blob, {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 1});              // positions, 48 bytes at 0
  put<uint16_t>(d.blob, {0, 1, 2, 1, 3, 2});                             // indices, 12 bytes at 48
  put<float>(d.blob, {1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1});  // tangents, 64 bytes at 60
  d.j["accessors"] = {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
                      {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}},
                      {{"bufferView", 2}, {"componentType", 5126}, {"count", 4}, {"type", "VEC4"}}};
  d.j["bufferViews"] = {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
                        {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 12}},
                        {{"buffer", 0}, {"byteOffset", 60}, {"byteLength", 64}}};
  d.j["buffers"][0]["byteLength"] = 124;
  d.j["meshes"][0]["primitives"][0] = {
      {"attributes", {{"POSITION", 0}, {"TANGENT", 2}}}, {"indices", 1}, {"material", 0}};
  d.j["materials"][0]["normalTexture"] = {{"index", 0}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["images"] = {{{"uri", red_blue_png_uri()}}};
  const Scene s = load(d);
  const Mesh& m = s.meshes.at(0);
  EXPECT_TRUE(m.flat);
  EXPECT_TRUE(m.tangents.empty());
  for (const Vec3& n : m.normals) EXPECT_EQ(length(n), 0.0f);
  // Each triangle's surface point shades with that triangle's normal, up to its edges.
  for (uint32_t prim = 0; prim < 2; ++prim) {
    Hit hit;
    hit.shape = 0;
    hit.prim = prim;
    hit.u = 0.45f, hit.v = 0.45f;
    hit.t = 1;
    const SurfacePoint sp = make_surface_point(s, Ray{Vec3{0.3f, 0.3f, 2}, Vec3{0, 0, -1}, 0, 10}, hit);
    EXPECT_LT(length(sp.ns - sp.ng), 1e-7f) << prim;
  }
  // With NORMAL, the file's normals shade as before.
  Doc smooth;
  EXPECT_FALSE(load(smooth).meshes.at(0).flat);
}

}  // namespace
}  // namespace tessera
