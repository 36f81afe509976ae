// Issue 29: compressed glTF geometry decodes to its uncompressed twin (EXT_meshopt_compression
// vertex and index streams, KHR_draco_mesh_compression), and damaged or lying streams are
// refused naming the view or primitive. The compressed data is made here with the same
// libraries' encoders.
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <meshoptimizer.h>

#include <algorithm>

#include "tests/core/gltf_fixture.h"  // first: see below

namespace tessera {
namespace {

// The fixture's positions (3 vertices) and indices as a meshopt-compressed twin: buffer 1 is
// the fallback the views point at, buffer 0 holds the compressed streams.
Doc meshopt_twin(bool truncate = false) {
  Doc d;
  const float* pos = reinterpret_cast<const float*>(d.blob.data());
  std::vector<unsigned char> vbuf(meshopt_encodeVertexBufferBound(3, 12));
  vbuf.resize(meshopt_encodeVertexBuffer(vbuf.data(), vbuf.size(), pos, 3, 12));
  const unsigned int idx[3] = {0, 1, 2};
  std::vector<unsigned char> ibuf(meshopt_encodeIndexBufferBound(3, 3));
  ibuf.resize(meshopt_encodeIndexBuffer(ibuf.data(), ibuf.size(), idx, 3));
  if (truncate) vbuf.resize(vbuf.size() / 2);
  auto append = [&](const std::vector<unsigned char>& bytes) {
    while (d.blob.size() % 4) d.blob.push_back('\0');
    const size_t at = d.blob.size();
    d.blob.append(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    return at;
  };
  const size_t v_at = append(vbuf), i_at = append(ibuf);
  d.j["buffers"][0]["byteLength"] = d.blob.size();
  d.j["buffers"].push_back({{"byteLength", 48}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
  d.j["bufferViews"][0] = {{"buffer", 1},
                           {"byteOffset", 0},
                           {"byteLength", 36},
                           {"byteStride", 12},
                           {"extensions",
                            {{"EXT_meshopt_compression",
                              {{"buffer", 0},
                               {"byteOffset", v_at},
                               {"byteLength", vbuf.size()},
                               {"byteStride", 12},
                               {"count", 3},
                               {"mode", "ATTRIBUTES"}}}}}};
  d.j["bufferViews"][3] = {{"buffer", 1},
                           {"byteOffset", 36},
                           {"byteLength", 6},
                           {"extensions",
                            {{"EXT_meshopt_compression",
                              {{"buffer", 0},
                               {"byteOffset", i_at},
                               {"byteLength", ibuf.size()},
                               {"byteStride", 2},
                               {"count", 3},
                               {"mode", "TRIANGLES"}}}}}};
  d.j["extensionsUsed"] = {"EXT_meshopt_compression"};
  d.j["extensionsRequired"] = {"EXT_meshopt_compression"};
  return d;
}

TEST_F(Gltf, MeshoptCompressedViewsDecodeToTheirTwin) {
  const Scene plain = load(Doc());
  const Scene packed = load(meshopt_twin());
  ASSERT_EQ(packed.meshes.size(), 1u);
  EXPECT_EQ(packed.meshes[0].indices, plain.meshes[0].indices);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(packed.meshes[0].positions[i].x, plain.meshes[0].positions[i].x);
    EXPECT_EQ(packed.meshes[0].positions[i].y, plain.meshes[0].positions[i].y);
    EXPECT_EQ(packed.meshes[0].positions[i].z, plain.meshes[0].positions[i].z);
  }
  expect_error(meshopt_twin(true), "bufferViews[0] EXT_meshopt_compression: the compressed data is damaged");
  Doc bad = meshopt_twin();
  bad.j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["mode"] = "POINTS";
  expect_error(bad, "mode 'POINTS' is not ATTRIBUTES, TRIANGLES or INDICES");
  bad = meshopt_twin();
  bad.j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteLength"] = 1 << 20;
  expect_error(bad, "runs past buffer 0");
  // A compressed view no accessor reads is not decoded (40 of them sharing 1 MB of
  // compressed bytes held 2.6 GB): a damaged one refuses nothing.
  Doc unused = meshopt_twin();
  json extra = unused.j["bufferViews"][0];
  extra["extensions"]["EXT_meshopt_compression"]["byteLength"] = 2;  // damaged
  unused.j["bufferViews"].push_back(extra);
  EXPECT_EQ(load(unused).meshes.size(), 1u);
}

// The fixture's triangle Draco-encoded (positions only; indices through the extension).
Doc draco_twin(bool truncate = false) {
  Doc d;
  draco::TriangleSoupMeshBuilder mb;
  mb.Start(1);
  const int pos = mb.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const float v[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  mb.SetAttributeValuesForFace(pos, draco::FaceIndex(0), v, v + 3, v + 6);
  const std::unique_ptr<draco::Mesh> mesh = mb.Finalize();
  draco::Encoder enc;
  draco::EncoderBuffer out;
  EXPECT_TRUE(enc.EncodeMeshToBuffer(*mesh, &out).ok());
  std::string bytes(out.data(), out.size());
  if (truncate) bytes.resize(bytes.size() / 2);
  while (d.blob.size() % 4) d.blob.push_back('\0');
  const size_t at = d.blob.size();
  d.blob += bytes;
  d.j["buffers"][0]["byteLength"] = d.blob.size();
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", bytes.size()}});
  auto& prim = d.j["meshes"][0]["primitives"][0];
  prim["attributes"] = {{"POSITION", 0}};
  prim["extensions"]["KHR_draco_mesh_compression"] = {
      {"bufferView", 4}, {"attributes", {{"POSITION", mesh->attribute(pos)->unique_id()}}}};
  d.j["accessors"][0].erase("bufferView");
  d.j["accessors"][3].erase("bufferView");
  d.j["extensionsUsed"] = {"KHR_draco_mesh_compression"};
  d.j["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  return d;
}

TEST_F(Gltf, DracoPrimitivesDecodeToTheirTwin) {
  const Scene s = load(draco_twin());
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  ASSERT_EQ(m.indices.size(), 3u);
  // The decoder may reorder the points: the triangle's corners are the same set.
  std::vector<std::array<float, 3>> corners, want = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  for (const uint32_t i : m.indices) corners.push_back({m.positions[i].x, m.positions[i].y, m.positions[i].z});
  std::sort(corners.begin(), corners.end());
  std::sort(want.begin(), want.end());
  EXPECT_EQ(corners, want);
  expect_error(draco_twin(true), "KHR_draco_mesh_compression: the Draco data does not decode");
  Doc lying = draco_twin();
  lying.j["accessors"][0]["count"] = 5;  // the accessor lies about the point count
  expect_error(lying, "POSITION: the Draco data has 3 points, accessors[0] says 5");
  lying = draco_twin();
  lying.j["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["attributes"]["POSITION"] = 7;
  expect_error(lying, "POSITION names Draco attribute 7, which the data lacks");
}

}  // namespace
}  // namespace tessera
