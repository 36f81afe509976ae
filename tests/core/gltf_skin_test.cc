// Issue 29: morph targets, skins and EXT_mesh_gpu_instancing, with known answers: a triangle morphed by weighted
// targets (mesh and node weights, animated weights), a bar bent by a joint through a
// known angle (rest pose and animated, the mesh node's own transform ignored, more than
// four influences), hostile skins refused naming what is wrong, instances placed by
// their own transforms under the node's, and TANGENTs placed as directions.
#include <cmath>

#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

// Appends `bytes` as a buffer view (4-byte aligned) and an accessor over it; returns the
// accessor's index.
int add_accessor(Doc& d, const std::string& bytes, int component_type, size_t count, const char* type) {
  while (d.blob.size() % 4) d.blob.push_back('\0');
  const size_t at = d.blob.size();
  d.blob += bytes;
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", bytes.size()}});
  d.j["buffers"][0]["byteLength"] = d.blob.size();
  d.j["accessors"].push_back({{"bufferView", d.j["bufferViews"].size() - 1},
                              {"componentType", component_type},
                              {"count", count},
                              {"type", type}});
  return int(d.j["accessors"].size() - 1);
}
template <typename T>
std::string bytes(std::initializer_list<T> v) {
  std::string s;
  put<T>(s, v);
  return s;
}
constexpr int kFloat = 5126, kUbyte = 5121;

void expect_vec(Vec3 a, Vec3 b, float tol = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

// The fixture's triangle (0,0,0), (1,0,0), (0,1,0) with two targets: +z everywhere (its
// normals turned toward +y), and +x at vertex 0 only.
Doc morphed() {
  Doc d;
  const int t0 = add_accessor(d, bytes<float>({0, 0, 1, 0, 0, 1, 0, 0, 1}), kFloat, 3, "VEC3");
  const int n0 = add_accessor(d, bytes<float>({0, 1, 0, 0, 1, 0, 0, 1, 0}), kFloat, 3, "VEC3");
  const int t1 = add_accessor(d, bytes<float>({1, 0, 0, 0, 0, 0, 0, 0, 0}), kFloat, 3, "VEC3");
  d.j["meshes"][0]["primitives"][0]["targets"] = {{{"POSITION", t0}, {"NORMAL", n0}}, {{"POSITION", t1}}};
  d.j["meshes"][0]["weights"] = {0.5, 0};
  return d;
}

TEST_F(Gltf, MorphTargetsMoveVerticesByTheirWeights) {
  Doc d = morphed();
  Scene s = load(d);
  expect_vec(s.meshes[0].positions[0], {0, 0, 0.5f});
  expect_vec(s.meshes[0].positions[1], {1, 0, 0.5f});
  expect_vec(s.meshes[0].normals[0], normalize(Vec3{0, 0.5f, 1}));
  // The node's weights replace the mesh's.
  d.j["nodes"][0]["weights"] = {1, 1};
  s = load(d);
  expect_vec(s.meshes[0].positions[0], {1, 0, 1});
  expect_vec(s.meshes[0].positions[2], {0, 1, 1});
  // Refused: a weight count that is not the target count; a NaN displacement.
  d.j["nodes"][0]["weights"] = {1};
  expect_error(d, "weights has 1 numbers for 2 morph targets");
  Doc bad = morphed();
  bad.blob.replace(size_t(bad.j["bufferViews"][4]["byteOffset"]), 4, bytes<float>({std::nanf("")}));
  expect_error(bad, "NaN");
  // A target with neither POSITION nor NORMAL moves nothing and holds nothing (2,000 empty
  // targets of a 100k-vertex mesh held 2.4 GB of zeros); its weight still counts as one.
  Doc empty = morphed();
  empty.j["meshes"][0]["primitives"][0]["targets"].push_back(json::object());
  empty.j["nodes"][0]["weights"] = {1, 1, 5};
  const Scene e = load(empty);
  expect_vec(e.meshes[0].positions[0], {1, 0, 1});
  expect_vec(e.meshes[0].positions[2], {0, 1, 1});
}

TEST_F(Gltf, AnimatedMorphWeightsArePosedPerFrame) {
  Doc d = morphed();
  const int times = add_accessor(d, bytes<float>({0, 1}), kFloat, 2, "SCALAR");
  const int values = add_accessor(d, bytes<float>({0, 0, 1, 0}), kFloat, 4, "SCALAR");  // 2 weights a key
  d.j["animations"] = {{{"channels", {{{"sampler", 0}, {"target", {{"node", 0}, {"path", "weights"}}}}}},
                        {"samplers", {{{"input", times}, {"output", values}}}}}};
  const Scene s = load(d);
  ASSERT_TRUE(s.animation);
  const Scene half = pose_scene(s, 0, 0.5);
  expect_vec(half.meshes[0].positions[1], {1, 0, 0.5f});
  expect_vec(pose_scene(s, 0, 1).meshes[0].positions[1], {1, 0, 1});
  // A weights channel on a node whose mesh has no targets is refused.
  d.j["meshes"][0]["primitives"][0].erase("targets");
  d.j["meshes"][0].erase("weights");
  expect_error(d, "whose mesh has no morph targets");
}

// The triangle (0,0,0), (2,0,0), (0,1,0) skinned by joint 0 at the origin and joint 1 at
// (1,0,0), its child: vertex 1 follows joint 1 alone, vertex 0 joint 0, vertex 2 half each
// (the second half through JOINTS_1 / WEIGHTS_1: more than four influences are read).
Doc skinned(float rest_angle_deg) {
  Doc d;
  d.blob.replace(0, 36, bytes<float>({0, 0, 0, 2, 0, 0, 0, 1, 0}));
  const int j0 = add_accessor(d, bytes<uint8_t>({0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0}), kUbyte, 3, "VEC4");
  const int w0 = add_accessor(d, bytes<float>({1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0, 0, 0}), kFloat, 3, "VEC4");
  const int j1 = add_accessor(d, bytes<uint8_t>({0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0}), kUbyte, 3, "VEC4");
  const int w1 = add_accessor(d, bytes<float>({0, 0, 0, 0, 0, 0, 0, 0, 0.5f, 0, 0, 0}), kFloat, 3, "VEC4");
  // Inverse bind matrices (column-major): identity, and a translation by -1 along x.
  const int ibm = add_accessor(d, bytes<float>({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0,  0, 0, 1,
                                                1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1}),
                               kFloat, 2, "MAT4");
  auto& attrs = d.j["meshes"][0]["primitives"][0]["attributes"];
  attrs["JOINTS_0"] = j0;
  attrs["WEIGHTS_0"] = w0;
  attrs["JOINTS_1"] = j1;
  attrs["WEIGHTS_1"] = w1;
  d.j["skins"] = {{{"joints", {2, 3}}, {"inverseBindMatrices", ibm}}};
  d.j["nodes"][0]["skin"] = 0;
  d.j["nodes"][0]["translation"] = {5, 0, 0};  // ignored: a skinned mesh follows its joints
  const double h = rest_angle_deg * M_PI / 360;
  d.j["nodes"].push_back({{"children", {3}}});
  d.j["nodes"].push_back({{"translation", {1, 0, 0}}, {"rotation", {0, 0, std::sin(h), std::cos(h)}}});
  d.j["scenes"][0]["nodes"] = {0, 1, 2};
  return d;
}

TEST_F(Gltf, ASkinBendsTheBarByTheJointsAngle) {
  Scene s = load(skinned(0));  // bind pose: the file's vertices
  expect_vec(s.meshes[0].positions[1], {2, 0, 0});
  expect_vec(s.meshes[0].positions[2], {0, 1, 0});
  s = load(skinned(90));  // joint 1 turned 90 degrees about z at rest: a still shows it
  expect_vec(s.meshes[0].positions[0], {0, 0, 0});
  expect_vec(s.meshes[0].positions[1], {1, 1, 0});
  // Vertex 2: half its bind place (0,1,0), half joint 1's image of it (0,-1,0).
  expect_vec(s.meshes[0].positions[2], {0, 0, 0});
  // Animated: joint 1 from 0 to 90 degrees; at half time, 45.
  Doc d = skinned(0);
  const int times = add_accessor(d, bytes<float>({0, 1}), kFloat, 2, "SCALAR");
  const float r = float(std::sin(M_PI / 4)), c = float(std::cos(M_PI / 4));
  const int values = add_accessor(d, bytes<float>({0, 0, 0, 1, 0, 0, r, c}), kFloat, 2, "VEC4");
  d.j["animations"] = {{{"channels", {{{"sampler", 0}, {"target", {{"node", 3}, {"path", "rotation"}}}}}},
                        {"samplers", {{{"input", times}, {"output", values}}}}}};
  const Scene a = load(d);
  ASSERT_TRUE(a.animation);
  const Scene p = pose_scene(a, 0, 0.5);
  const float k = float(std::sqrt(0.5));
  expect_vec(p.meshes[0].positions[1], {1 + k, k, 0});
  expect_vec(pose_scene(a, 0, 1).meshes[0].positions[1], {1, 1, 0});
}

TEST_F(Gltf, HostileSkinsAreRefusedByName) {
  Doc d = skinned(0);
  d.j["skins"][0]["joints"] = {2};  // vertex 1 names joint 1 of 1
  expect_error(d, "names joint 1");
  d = skinned(0);
  d.blob.replace(size_t(d.j["bufferViews"][5]["byteOffset"]), 4, bytes<float>({0.25f}));  // vertex 0 weighs 0.25
  expect_error(d, "the skin weights of vertex 0 sum to 0.25");
  d = skinned(0);
  d.j["meshes"][0]["primitives"][0]["attributes"].erase("WEIGHTS_1");
  expect_error(d, "has JOINTS_1 without WEIGHTS_1");
  d = skinned(0);
  d.j["skins"][0]["joints"] = {2, 99};
  expect_error(d, "joint node 99 does not exist");
  d = skinned(0);
  d.j["accessors"][8]["count"] = 1;  // one inverse bind matrix for two joints
  expect_error(d, "inverseBindMatrices has 1 matrices for 2 joints");
}

TEST_F(Gltf, GpuInstancesAreEachPlacedUnderTheNode) {
  Doc d;
  const int t = add_accessor(d, bytes<float>({0, 0, 0, 10, 0, 0, 0, 10, 0}), kFloat, 3, "VEC3");
  const float h = float(std::sqrt(0.5));
  const int r = add_accessor(d, bytes<float>({0, 0, 0, 1, 0, 0, h, h, 0, 0, 0, 1}), kFloat, 3, "VEC4");
  const int sc = add_accessor(d, bytes<float>({1, 1, 1, 1, 1, 1, 2, 2, 2}), kFloat, 3, "VEC3");
  d.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] = {
      {"TRANSLATION", t}, {"ROTATION", r}, {"SCALE", sc}};
  d.j["nodes"][0]["translation"] = {0, 0, -1};
  d.j["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
  const Scene s = load(d);
  ASSERT_EQ(s.meshes.size(), 1u);  // the triangle stored once, in its object space
  EXPECT_TRUE(s.meshes[0].instanced);
  expect_vec(s.meshes[0].positions[1], {1, 0, 0});
  ASSERT_EQ(s.instances.size(), 3u);
  EXPECT_EQ(s.triangle_count(), 3u);
  expect_vec(s.instances[0].point(s.meshes[0].positions[1]), {1, 0, -1});
  expect_vec(s.instances[1].point(s.meshes[0].positions[1]), {10, 1, -1});  // turned 90 degrees about z
  expect_vec(s.instances[2].point(s.meshes[0].positions[1]), {2, 10, -1});  // scaled by 2
  expect_vec(s.object_bounds().hi, {10, 12, -1});
  {  // In an animated file they are copies, posed with the node.
    Doc a = d;
    const int times = add_accessor(a, bytes<float>({0, 1, 2}), kFloat, 3, "SCALAR");
    const json channel = {{"sampler", 0}, {"target", {{"node", 0}, {"path", "translation"}}}};
    a.j["animations"] = json::array(
        {{{"channels", json::array({channel})}, {"samplers", json::array({{{"input", times}, {"output", t}}})}}});
    const Scene sa = load(a);
    EXPECT_EQ(sa.meshes.size(), 3u);
    EXPECT_TRUE(sa.instances.empty());
  }
  {  // A placement without an inverse (scaled to zero along an axis) is a copy in world
     // space, as a plain node with that scale is: a flat mesh in that plane keeps its
     // surface (it was left out, silently). A non-finite one is refused by name.
    Doc z = d;
    const int flat = add_accessor(z, bytes<float>({1, 1, 1, 1, 1, 0, 2, 2, 2}), kFloat, 3, "VEC3");
    z.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["SCALE"] = flat;
    const Scene sz = load(z);
    EXPECT_EQ(sz.instances.size(), 2u);
    ASSERT_EQ(sz.meshes.size(), 2u);
    EXPECT_FALSE(sz.meshes[1].instanced);
    expect_vec(sz.meshes[1].positions[1], {10, 1, -1});  // instance 1, turned 90 degrees about z
    EXPECT_EQ(sz.triangle_count(), 3u);
    const int huge = add_accessor(z, bytes<float>({1, 1, 1, 3e38f, 3e38f, 3e38f, 2, 2, 2}), kFloat, 3, "VEC3");
    z.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["SCALE"] = huge;
    z.j["nodes"][0]["scale"] = {10, 10, 10};
    expect_error(z, "EXT_mesh_gpu_instancing instance 1's transform is not finite");
  }
  EXPECT_TRUE(s.warnings.empty() || s.warnings[0].find("EXT_mesh_gpu_instancing") == std::string::npos);
  // Counts that disagree, or none, are refused by name.
  const int short_t = add_accessor(d, bytes<float>({0, 0, 0, 1, 1, 1}), kFloat, 2, "VEC3");
  d.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["TRANSLATION"] = short_t;
  expect_error(d, "EXT_mesh_gpu_instancing: ROTATION has 3 instances, the others 2");
  d.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] = json::object();
  expect_error(d, "has no instances");
}

TEST_F(Gltf, TangentsAreReadWhereANormalMapUsesThem) {
  Doc d;
  // The node turned 90 degrees about z and mirrored in x: (1, 0, 0) -> (0, 1, 0) -> (0, 1, 0).
  const float h = float(std::sqrt(0.5));
  d.j["nodes"][0]["rotation"] = {0, 0, h, h};
  d.j["nodes"][0]["scale"] = {1, 1, -1};
  const int tan = add_accessor(d, bytes<float>({1, 0, 0, 1, 1, 0, 0, -1, 1, 0, 0, 1}), kFloat, 3, "VEC4");
  d.j["meshes"][0]["primitives"][0]["attributes"]["TANGENT"] = tan;
  EXPECT_TRUE(load(d).meshes[0].tangents.empty());  // no normal map: not read
  d.j["images"] = {{{"uri", red_blue_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  d.j["materials"][0]["normalTexture"] = {{"index", 0}};
  const Scene s = load(d);
  ASSERT_EQ(s.meshes[0].tangents.size(), 3u);
  expect_vec(s.meshes[0].tangents[0].t, {0, 1, 0});
  // det < 0 (the mirror): each sign turns.
  EXPECT_EQ(s.meshes[0].tangents[0].sign, -1.0f);
  EXPECT_EQ(s.meshes[0].tangents[1].sign, 1.0f);
  {  // An animated node turns them with each pose: no turn at 0 s, 90 degrees about z at 1 s.
    Doc a = d;
    const int times = add_accessor(a, bytes<float>({0, 1}), kFloat, 2, "SCALAR");
    const int turns = add_accessor(a, bytes<float>({0, 0, 0, 1, 0, 0, h, h}), kFloat, 2, "VEC4");
    const json channel = {{"sampler", 0}, {"target", {{"node", 0}, {"path", "rotation"}}}};
    a.j["animations"] = json::array(
        {{{"channels", json::array({channel})}, {"samplers", json::array({{{"input", times}, {"output", turns}}})}}});
    const Scene rest = load(a);
    const Scene at0 = pose_scene(rest, 0, 0), at1 = pose_scene(rest, 0, 1);
    expect_vec(at0.meshes[0].tangents[0].t, {1, 0, 0});
    expect_vec(at1.meshes[0].tangents[0].t, {0, 1, 0});
    EXPECT_EQ(at1.meshes[0].tangents[0].sign, -1.0f);
  }
  const int short_tan = add_accessor(d, bytes<float>({1, 0, 0, 1}), kFloat, 1, "VEC4");
  d.j["meshes"][0]["primitives"][0]["attributes"]["TANGENT"] = short_tan;
  expect_error(d, "TANGENT count differs from POSITION count");
}

}  // namespace
}  // namespace tessera
