// The glTF loader refuses hostile and damaged files with a clear error, never a crash or a
// huge allocation.
#include "core/scene/gltf/gltf_animation.h"
#include "core/scene/gltf/gltf_compression.h"
#include "core/scene/gltf/gltf_materials.h"
#include "core/scene/gltf/gltf_nodes.h"
#include "core/util/cancel.h"
#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

// ---- refused, with a clear message ---------------------------------------------------

TEST_F(Gltf, RequiredUnsupportedExtensionIsRefusedByName) {
  Doc d;
  d.j["extensionsUsed"] = {"KHR_materials_pbrSpecularGlossiness"};
  d.j["extensionsRequired"] = {"KHR_materials_pbrSpecularGlossiness"};
  expect_error(d, "required extension 'KHR_materials_pbrSpecularGlossiness' is not supported");
}

// COLOR_0 and TEXCOORD_1 (issue 29) are checked as every attribute is: a count that is not
// the vertices' or a wrong shape is refused naming the attribute.
TEST_F(Gltf, ColoursAndASecondCoordinateSetOfTheWrongSizeAreRefused) {
  Doc d;  // accessor 3 is the 3 indices: a SCALAR, 3 of them
  d.j["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"] = 3;
  expect_error(d, "COLOR_0");
  Doc e;  // two coordinates for three vertices
  e.j["accessors"].push_back(
      {{"bufferView", 2}, {"componentType", 5121}, {"normalized", true}, {"count", 2}, {"type", "VEC2"}});
  e.j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = 4;
  expect_error(e, "TEXCOORD_1 count differs from POSITION count");
}

TEST_F(Gltf, AModeThatIsNoGltfModeIsRefused) {
  Doc d;
  d.j["meshes"][0]["primitives"][0]["mode"] = 9;
  expect_error(d, "mode 9 is not a glTF mode (0-6)");
}

// Issue 29: points and lines are skipped with a warning (the file still renders); strips
// and fans are triangles in the specification's order.
TEST_F(Gltf, PointsAndLinesAreSkippedWithAWarningNotRefused) {
  Doc d;
  json line = d.j["meshes"][0]["primitives"][0];
  line["mode"] = 1;
  d.j["meshes"][0]["primitives"].push_back(line);
  const Scene s = load(d);
  size_t triangles = 0;
  for (const Mesh& m : s.meshes) triangles += m.indices.size() / 3;
  EXPECT_EQ(triangles, 1u);
  bool warned = false;
  for (const std::string& w : s.warnings)
    warned |= w.find("meshes[0].primitives[1]: mode LINES has no surface to render: skipped") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST_F(Gltf, StripsAndFansBecomeTrianglesInTheSpecificationsOrder) {
  for (const int mode : {5, 6}) {  // TRIANGLE_STRIP, TRIANGLE_FAN
    Doc d;                         // four vertices: (0,0) (1,0) (0,1) (1,1), no index accessor
    d.blob.clear();
    put<float>(d.blob, {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0});
    json& prim = d.j["meshes"][0]["primitives"][0];
    prim = {{"attributes", {{"POSITION", 0}}}, {"mode", mode}};
    d.j["accessors"] = {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}}};
    d.j["bufferViews"] = {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}}};
    d.j["buffers"][0]["byteLength"] = 48;
    const Scene s = load(d);
    ASSERT_EQ(s.meshes.size(), 1u);
    const std::vector<uint32_t> want = mode == 5 ? std::vector<uint32_t>{0, 1, 2, 1, 3, 2}   // strip: both CCW
                                                 : std::vector<uint32_t>{1, 2, 0, 2, 3, 0};  // fan
    EXPECT_EQ(s.meshes[0].indices, want) << "mode " << mode;
  }
}

TEST_F(Gltf, AnOrthographicCameraIsReadAndAnUnusableOneRefused) {
  Doc d;
  d.j["cameras"][0] = {{"type", "orthographic"},
                       {"orthographic", {{"xmag", 2}, {"ymag", -1}, {"znear", 0.1}, {"zfar", 10}}}};
  const Scene s = load(d);
  ASSERT_TRUE(s.camera.ortho_half_height);
  EXPECT_EQ(*s.camera.ortho_half_height, 1);
  EXPECT_EQ(*s.camera.aspect_ratio, 2);
  EXPECT_FLOAT_EQ(s.camera.znear, 0.1f);
  EXPECT_FLOAT_EQ(s.camera.eye.z, 3);
  d.j["cameras"][0]["orthographic"]["ymag"] = 0;
  expect_error(d, "orthographic xmag and ymag must be finite, not zero and within +-1e12");
  d.j["cameras"][0]["orthographic"]["ymag"] = 1;
  d.j["cameras"][0]["orthographic"]["zfar"] = 0.05;
  expect_error(d, "orthographic needs 0 <= znear < zfar");
}

TEST_F(Gltf, AccessorOffsetPastTheBufferView) {
  Doc d;
  d.j["accessors"][0]["byteOffset"] = 8;
  expect_error(d, "runs past the end of bufferView 0");
}

TEST_F(Gltf, BufferViewPastTheBuffer) {
  Doc d;
  d.j["bufferViews"][1]["byteLength"] = 4000;
  expect_error(d, "runs past the end of its buffer");
  // Found by review: byteOffset + byteLength could wrap past 2^64 to pass the check, and an
  // image's view went to the image loader unchecked (tinygltf reads it even where no
  // material uses the image): both read past the buffer. Every view is checked first.
  Doc wrap;
  wrap.j["bufferViews"][1]["byteOffset"] = 1;
  wrap.j["bufferViews"][1]["byteLength"] = 18446744073709551615ull;
  expect_error(wrap, "bufferViews[1]: runs past the end of its buffer (byteOffset 1 + byteLength");
  Doc image;
  image.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 80}, {"byteLength", 1000000000}});
  image.j["images"] = {{{"bufferView", 4}, {"mimeType", "image/png"}}};
  expect_error(image, "bufferViews[4]: runs past the end of its buffer (byteOffset 80 + byteLength 1000000000 > 88");
}

TEST_F(Gltf, IndexOutOfRange) {
  Doc d;
  std::memcpy(d.blob.data() + 82, "\x09\x00", 2);  // second index = 9 with 3 vertices
  expect_error(d, "index 9 out of range (3 vertices)");
}

TEST_F(Gltf, BufferShorterThanDeclared) {
  Doc d;
  d.j["buffers"][0]["uri"] = "short.bin";
  write("short.bin", d.blob.substr(0, 40));
  expect_error(write(d, false), "short.bin");
  try {  // tinygltf names the file by its absolute path: only the scene's name is shown
    load_scene(write(d, false));
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()).find(dir.string(), 1), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("a buffer's file is not the size its byteLength says"), std::string::npos)
        << e.what();
  }
}

// Found by fuzz_gltf: a number too large for a double (1e999) made the JSON parser throw
// an exception the loader did not expect, and the process ended.
TEST_F(Gltf, NumberBeyondADoubleIsAnError) {
  expect_error(write("scene.gltf", R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"x":1e999})"), "JSON");
}

// Tolerant where viewers and the course's renderer are: data nothing uses is never read, so
// a malformed unused accessor is a warning and a broken unused image nothing at all; the
// same data in use is still the one-line error.
TEST_F(Gltf, MalformedDataNothingUsesIsToleratedAndInUseRefused) {
  Doc d;
  d.j["accessors"].push_back({{"count", "many"}, {"type", "VEC3"}});  // no componentType, count not a number
  const size_t bad = d.j["accessors"].size() - 1;
  d.j["images"] = {{{"uri", "data:image/png;base64,bm90IGFuIGltYWdl"}}};  // "not an image"
  d.j["textures"] = {{{"source", 0}}};
  const Scene s = load(d);
  EXPECT_EQ(s.meshes.size(), 1u);
  bool warned = false;
  for (const std::string& w : s.warnings)
    warned |= w.find("accessors[" + std::to_string(bad) + "] has no valid componentType; nothing uses it: ignored") !=
              std::string::npos;
  EXPECT_TRUE(warned);
  // The same image used by a material: refused, naming it.
  Doc used = d;
  used.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
  expect_error(used, "images[0]: not a PNG, JPEG or WebP image");
  // A KTX2 file named as a plain image source (no KHR_texture_basisu): said so, with the way out.
  used.j["images"][0]["uri"] = "data:image/png;base64,q0tUWCAyMLsNChoKAAAAAAAAAAAAAAAAAAAAAAAAAAA=";
  expect_error(used, "images[0]: is a KTX2 image, which Tessera cannot decode");
  // The same accessor used as indices: refused (by tinygltf's parser).
  Doc idx = d;
  idx.j["meshes"][0]["primitives"][0]["indices"] = bad;
  std::string error;
  try {
    load(idx);
  } catch (const SceneError& e) {
    error = e.what();
  }
  EXPECT_FALSE(error.empty()) << "a malformed accessor in use loaded";
  // In a .glb too: the JSON chunk is rewritten around the unused accessor.
  Doc glb = d;
  glb.j["buffers"][0].erase("uri");
  const Scene g = load_gltf_file(write("scene.glb", glb_file(glb.j.dump(), glb.blob)));
  EXPECT_EQ(g.meshes.size(), 1u);
}

// A .glb whose BIN chunk is not padded to 4 bytes: refused in a user's words.
TEST_F(Gltf, AnUnpaddedGlbBinChunkIsRefusedInPlainWords) {
  Doc d;
  d.j["buffers"][0].erase("uri");
  expect_error(write("scene.glb", glb_file(d.j.dump(), d.blob + "xy", false)),  // 90 bytes
               "the .glb's BIN chunk length is not a multiple of 4 bytes");
}

// Found by review: tinygltf's walk of a parsed document recurses once a level, and 20,000
// nested arrays in a 40 KB file (an upload to a coordinator, which loads it itself) ended
// the process with a stack overflow. Refused before either parser sees it, .glb too;
// brackets inside strings do not count, and nesting up to the limit loads.
TEST_F(Gltf, JsonNestedDeeperThanTheLimitIsRefusedBeforeParsing) {
  Doc d;
  d.embed();
  auto with_extras = [&](size_t depth, const std::string& text) {
    return "{\"extras\":" + std::string(depth, '[') + text + std::string(depth, ']') + "," + d.j.dump().substr(1);
  };
  expect_error(write("scene.gltf", with_extras(20000, "")), "arrays and objects nested deeper than 256 levels");
  Doc bin = d;
  bin.j["buffers"][0].erase("uri");
  const std::string glb_json =
      "{\"extras\":" + std::string(20000, '[') + std::string(20000, ']') + "," + bin.j.dump().substr(1);
  expect_error(write("scene.glb", glb_file(glb_json, bin.blob)), "arrays and objects nested deeper than 256 levels");
  // The root object and 255 arrays: 256 levels, loaded; a string of brackets is text.
  EXPECT_EQ(load_gltf_file(write("scene.gltf", with_extras(255, "\"[[[[{{{{\\\"\""))).meshes.size(), 1u);
}

TEST_F(Gltf, BrokenBase64) {
  Doc d;
  d.embed();
  std::string uri = d.j["buffers"][0]["uri"];
  uri.replace(uri.size() - 20, 10, "!!**??%%^^");
  d.j["buffers"][0]["uri"] = uri;
  try {
    load_gltf_file(write("scene.gltf", d.j.dump()));
    ADD_FAILURE() << "broken base64 loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("scene.gltf"), std::string::npos) << e.what();
  }
}

TEST_F(Gltf, TenGigabyteByteLengthIsRefusedBeforeAllocating) {
  Doc d;
  d.j["buffers"][0]["byteLength"] = 10737418240.0;
  expect_error(d, "byteLength 10737418240 is over the 1 GiB limit");
  // Every buffer is read, used or not (one 100 MB file named by 20 buffers held 2 GB):
  // together they are bounded too.
  Doc many;
  for (int i = 0; i < 3; ++i) many.j["buffers"].push_back({{"uri", "big.bin"}, {"byteLength", 1 << 30}});
  expect_error(many, "buffers[2]: the buffers up to this one declare 2147483736 bytes together, over the 2 GiB limit");
  // EXT_meshopt_compression's fallback buffers hold no data: they do not count.
  Doc fallbacks;
  for (int i = 0; i < 3; ++i)
    fallbacks.j["buffers"].push_back(
        {{"byteLength", 1 << 30}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
  fallbacks.j["extensionsUsed"] = {"EXT_meshopt_compression"};
  EXPECT_EQ(load(fallbacks).meshes.size(), 1u);
}

TEST_F(Gltf, CyclicNodeGraph) {
  Doc d;
  d.j["nodes"][0]["children"] = {2};
  d.j["nodes"].push_back({{"children", {0}}});
  expect_error(d, "the node graph has a cycle");
}

TEST_F(Gltf, SelfParentNode) {
  Doc d;
  d.j["nodes"][0]["children"] = {0};
  expect_error(d, "nodes[0]: the node graph has a cycle");
}

// Issue 23: a node graph that lists a child twice, nested 30 deep, expanded to 2^30 meshes
// (a 1 KB file, 1 GB and counting); without meshes it pinned a core for days. The budget
// counts the expansion before the walk and refuses it naming the limit.
TEST_F(Gltf, DagBombsAreRefusedBeforeExpansion) {
  auto bomb = [](bool with_mesh, int levels) {
    Doc d;
    if (!with_mesh) d.j["nodes"][0].erase("mesh");
    for (int i = 1; i <= levels; ++i) {
      const int child = i == 1 ? 0 : int(d.j["nodes"].size()) - 1;
      d.j["nodes"].push_back({{"children", {child, child}}});
    }
    d.j["scenes"][0]["nodes"] = {int(d.j["nodes"].size()) - 1, 1};
    return d;
  };
  expect_error(bomb(true, 30), "the scene's node graph expands to 2147483648 node visits");
  expect_error(bomb(false, 60), "node visits (a child listed more than once is expanded each time), over the limit");
  // Within the visits, a mesh copied 1 M times and more (2 M one-triangle copies: 2 GB, 15
  // s to check): refused too.
  Doc many = bomb(true, 19);
  for (int i = 0; i < 2; ++i) many.j["meshes"][0]["primitives"].push_back(many.j["meshes"][0]["primitives"][0]);
  expect_error(many, "the scene's node graph expands to 1572864 meshes (a mesh is copied at each visit");
  // A child listed twice a few times over is an instance, rendered twice each time.
  const Scene s = load(bomb(true, 4));
  EXPECT_EQ(s.meshes.size(), 16u);
}

// Issue 23: a long load can be stopped (a coordinator's scene check whose client went away,
// or a coordinator told to stop): under a CancelScope it polls at each node, primitive and
// texture and throws Cancelled; without one (tessera render, workers) it never does.
TEST_F(Gltf, ALoadUnderACancelScopeStopsAtItsNextStep) {
  Doc d;
  for (int i = 1; i <= 10; ++i) {  // 1024 visits of the mesh
    const int child = i == 1 ? 0 : int(d.j["nodes"].size()) - 1;
    d.j["nodes"].push_back({{"children", {child, child}}});
  }
  d.j["scenes"][0]["nodes"] = {int(d.j["nodes"].size()) - 1};
  const std::string path = write(d);
  int polls = 0;
  {
    const CancelScope scope([&] { return ++polls > 100; }, 0);  // asked at every step
    EXPECT_THROW(load_gltf_file(path), Cancelled);
  }
  EXPECT_EQ(polls, 101);                                 // stopped at the first step after it was asked to
  EXPECT_EQ(load_gltf_file(path).meshes.size(), 1024u);  // no scope: loads
  {
    const CancelScope scope([] { return false; });
    EXPECT_EQ(load_gltf_file(path).meshes.size(), 1024u);
  }
}

// Triangles are counted before expansion too, instances of EXT_mesh_gpu_instancing included.
TEST_F(Gltf, TrianglesOverTheBudgetAreRefusedBeforeExpansion) {
  Doc d;
  d.j["accessors"][3]["count"] = 3 * 40'000'000;  // declared; never read
  for (int i = 0; i < 2; ++i) d.j["nodes"].push_back({{"children", {0, 0}}});
  d.j["nodes"][3]["children"] = {2, 2};
  d.j["scenes"][0]["nodes"] = {3};
  expect_error(d, "nodes: the scene expands to 160000000 triangles");
}

// Each kind a load holds has a limit of its own, but within all of them a small file could
// still ask for about 20 GB: here a mesh of 570 (declared) vertices copied 2^19 times by its
// node graph, 99.6 M triangles (under the 100 M limit) in 524,288 mesh copies (under 2^20),
// would be 10 GiB of vertex arrays. The load-wide bound refuses it before the expansion,
// naming what it would hold, kind by kind.
TEST_F(Gltf, WhatALoadHoldsIsBoundedAllKindsTogether) {
  Doc d;
  d.j["accessors"][0]["count"] = 570;  // declared; never read
  d.j["accessors"][3]["count"] = 570;
  for (int i = 1; i <= 19; ++i) {
    const int child = i == 1 ? 0 : int(d.j["nodes"].size()) - 1;
    d.j["nodes"].push_back({{"children", {child, child}}});
  }
  d.j["scenes"][0]["nodes"] = {int(d.j["nodes"].size()) - 1, 1};
  expect_error(d,
               "nodes: the scene would take 10.02 GiB to load (buffers 88 bytes, meshes 10.02 GiB), over the 8.00 "
               "GiB limit of a glTF load, all kinds together");
}

// Found by review: instances without an inverse transform (a zero scale) are copies even
// where the budget counts real instances' mesh once; each copy is charged before it is
// read. The load below, step by step as load_gltf_file takes it, with its bound lowered:
// 88 bytes of buffer, the mesh (3 vertices with positions, normals and uvs, 1 triangle:
// 108 bytes) counted by the budget and then 3 times again, once for each copy.
TEST_F(Gltf, InstancesCopiedForWantOfAnInverseAreChargedEach) {
  Doc d;
  d.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] = {{"SCALE", 1}};  // (0, 0, 1) x 3
  d.j["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
  const std::string path = write(d);
  auto load_within = [&](uint64_t max_load_bytes) {
    GltfContext ctx(path);
    ctx.max_load_bytes = max_load_bytes;
    parse_gltf_model(read_gltf_document(path), ctx);
    decode_gltf_compression(ctx);
    GltfMaterials materials(ctx);
    GltfAnimationBuilder animation(false);
    add_gltf_nodes(ctx, materials, animation);
    EXPECT_EQ(ctx.scene.meshes.size(), 4u);  // the instanced one, unused, and 3 copies
    return ctx.load_bytes();
  };
  EXPECT_EQ(load_within(kMaxGltfLoadBytes), 88u + 4 * 108);
  try {
    load_within(88 + 4 * 108 - 1);
    ADD_FAILURE() << "loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("nodes[0]: the scene would take 520 bytes to load (buffers 88 bytes, meshes "
                                         "432 bytes), over the 519 bytes limit"),
              std::string::npos)
        << e.what();
  }
}

// Found by audit: each image entry keeps its own copy of its encoded bytes, uncounted, so a
// small file naming one 20 MB bufferView a hundred times held 2 GB (five hundred: a bare
// std::bad_alloc). The copies count against the load's bound as they are made.
TEST_F(Gltf, EncodedImagesCountAgainstTheLoadsBound) {
  Doc d;
  for (int i = 0; i < 3; ++i) d.j["images"].push_back({{"bufferView", 0}, {"mimeType", "image/png"}});  // 36 bytes each
  const std::string path = write(d);
  auto load_within = [&](uint64_t max_load_bytes) {
    GltfContext ctx(path);
    ctx.max_load_bytes = max_load_bytes;
    parse_gltf_model(read_gltf_document(path), ctx);
    return ctx.load_bytes();
  };
  EXPECT_EQ(load_within(kMaxGltfLoadBytes), 88u + 3 * 36);
  try {
    load_within(100);
    ADD_FAILURE() << "loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("images[2]: the images' encoded bytes pass"), std::string::npos) << e.what();
  }
  try {
    load_within(88 + 3 * 36 - 1);  // each copy within it, the load not
    ADD_FAILURE() << "loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("(buffers 88 bytes, encoded images 108 bytes)"), std::string::npos)
        << e.what();
  }
}

// EXT_mesh_gpu_instancing: real instances store the mesh once, so 3 instances of a mesh of
// 40 M (declared) triangles pass the budget (and fail later, on the buffer that does not
// hold them); in a file with animations they would be copies: 120 M, refused.
TEST_F(Gltf, RealInstancesCountTheirMeshOnceCopiesEachTime) {
  Doc d;
  d.j["accessors"][3]["count"] = 3 * 40'000'000;  // declared; never read
  d.j["nodes"][0]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"] = {{"TRANSLATION", 0}};  // 3
  d.j["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
  try {
    load(d);
    FAIL() << "loaded";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()).find("the scene expands to"), std::string::npos) << e.what();
  }
  d.j["animations"] = json::array({{{"channels", json::array()}, {"samplers", json::array()}}});
  expect_error(d, "nodes: the scene expands to 120000000 triangles");
}

TEST_F(Gltf, HierarchyDeeperThanTheLimitIsRefused) {
  Doc d;
  for (int i = 0; i < 300; ++i) d.j["nodes"].push_back({{"children", {int(d.j["nodes"].size()) - 1}}});
  d.j["nodes"][2]["children"] = {0};
  d.j["scenes"][0]["nodes"] = {int(d.j["nodes"].size()) - 1};
  expect_error(d, "node hierarchy deeper than 256 levels");
}

TEST_F(Gltf, UriOutsideTheScenesFolderIsRefused) {
  Doc d;
  write("secret.bin", d.blob);
  fs::create_directories(dir / "sub");
  d.j["buffers"][0]["uri"] = "../secret.bin";
  const std::string path = (dir / "sub" / "scene.gltf").string();
  std::ofstream(path) << d.j.dump();
  expect_error(path, "outside the scene's folder");
}

TEST_F(Gltf, GarbageAndTruncatedFiles) {
  expect_error(write("junk.gltf", std::string(100, '\x07')), "JSON");
  Doc d;
  d.embed();
  const std::string full = d.j.dump();
  expect_error(write("cut.gltf", full.substr(0, full.size() / 2)), "JSON");
  std::string glb = "glTF";
  put<uint32_t>(glb, {2, 1000000, 50, 0x4E4F534Au});
  expect_error(write("cut.glb", glb), "GLB header");
}

TEST_F(Gltf, NaNPositionIsRefused) {
  Doc d;
  const float nan = std::nanf("");
  std::memcpy(d.blob.data() + 4, &nan, 4);
  expect_error(d, "NaN or infinite");
}

TEST_F(Gltf, AccessorWithTheWrongShape) {
  Doc d;
  d.j["accessors"][0]["type"] = "VEC2";
  expect_error(d, "has 2 components, expected 3");
}

}  // namespace
}  // namespace tessera
