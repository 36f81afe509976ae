// The loader's units (core/scene/gltf/) on their own.
#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

// The model's buffer 0 holds `bytes`; view k covers views[k] = (byteOffset, byteLength) of it.
void set_buffer(GltfContext& ctx, const std::string& bytes, std::vector<std::pair<size_t, size_t>> views) {
  ctx.model.buffers.resize(1);
  ctx.model.buffers[0].data.assign(bytes.begin(), bytes.end());
  ctx.model.bufferViews.resize(views.size());
  for (size_t k = 0; k < views.size(); ++k) {
    ctx.model.bufferViews[k].buffer = 0;
    ctx.model.bufferViews[k].byteOffset = views[k].first;
    ctx.model.bufferViews[k].byteLength = views[k].second;
  }
}

// Runs f, which must refuse with a SceneError whose message holds `reason`; `what` says
// what would have been done wrongly otherwise.
template <class F>
void expect_refused(F&& f, const std::string& reason, const std::string& what) {
  try {
    f();
    ADD_FAILURE() << what;
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find(reason), std::string::npos) << e.what();
  }
}

// An accessor of `count` elements of `type` (TINYGLTF_TYPE_*) and `component` over `view`.
tinygltf::Accessor accessor(int view, int component, size_t count, int type) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.componentType = component;
  a.count = count;
  a.type = type;
  return a;
}

// The pre-checks on JSON alone: what tinygltf would refuse is set aside only when nothing
// uses it, and anything a mesh (attributes, indices, morph targets), an animation or a
// skin names counts as used.
TEST(GltfPrechecks, OnlyMalformedAccessorsNothingUsesAreSetAside) {
  const json bad = {{"count", 3}, {"type", "VEC3"}};  // no componentType
  json j = {{"asset", {{"version", "2.0"}}},
            {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"targets", {{{"POSITION", 1}}}}}}}}}},
            {"animations", {{{"samplers", {{{"input", 2}, {"output", 2}}}}}}},
            {"skins", {{{"inverseBindMatrices", 3}}}},
            {"accessors", {bad, bad, bad, bad, bad}}};
  std::vector<std::string> warnings;
  EXPECT_TRUE(precheck_gltf_json(j, "f.gltf", warnings));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0], "f.gltf: accessors[4] has no valid componentType; nothing uses it: ignored");
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(j["accessors"][i], bad) << i;
  EXPECT_EQ(j["accessors"][4], json({{"componentType", 5126}, {"count", 0}, {"type", "SCALAR"}}));
  // Nothing left to set aside: unchanged.
  warnings.clear();
  EXPECT_FALSE(precheck_gltf_json(j, "f.gltf", warnings));
  EXPECT_TRUE(warnings.empty());
}

TEST(GltfPrechecks, RefusalsNameTheElement) {
  auto refusal = [](json j) -> std::string {
    std::vector<std::string> warnings;
    try {
      precheck_gltf_json(j, "f.gltf", warnings);
    } catch (const SceneError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(refusal(json::array()).find("JSON: top level is not an object"), std::string::npos);
  EXPECT_NE(refusal({{"extensionsRequired", {"KHR_materials_pbrSpecularGlossiness"}}})
                .find("extensionsRequired: required extension 'KHR_materials_pbrSpecularGlossiness' is not supported"),
            std::string::npos);
  EXPECT_NE(refusal({{"buffers", {{{"byteLength", 8}}, {{"uri", "a.bin"}}}}}).find("buffers[1]: missing byteLength"),
            std::string::npos);
  EXPECT_EQ(refusal({{"extensionsRequired", {"KHR_materials_volume"}}, {"buffers", {{{"byteLength", 1 << 30}}}}}), "");
}

class GltfDocumentTest : public Gltf {};

// The JSON of a .glb is its chunk 0, found by the file's first bytes whatever its name;
// external files are those outside it, percent-decoded, each once.
TEST_F(GltfDocumentTest, GlbChunkAndExternalFiles) {
  const json j = {{"buffers", {{{"uri", "a%20b.bin"}}, {{"uri", "data:application/octet-stream;base64,AAAA"}}}},
                  {"images", {{{"uri", "tex/c.png"}}, {{"uri", "a b.bin"}}, {{"bufferView", 0}}}}};
  std::string text = j.dump();
  while (text.size() % 4) text += ' ';
  std::string glb = "glTF";
  put<uint32_t>(glb, {2, uint32_t(20 + text.size()), uint32_t(text.size()), 0x4E4F534Au});
  glb += text;
  const GltfDocument doc = read_gltf_document(write("named.gltf", glb));
  EXPECT_TRUE(doc.binary);
  EXPECT_EQ(doc.json, j);
  EXPECT_EQ(gltf_document_external_files(doc.json), (std::vector<std::string>{"a b.bin", "tex/c.png"}));
  EXPECT_EQ(gltf_external_files(write("text.gltf", j.dump())), (std::vector<std::string>{"a b.bin", "tex/c.png"}));
}

// Accessors read from an in-memory model: interleaved (byteStride), normalized signed
// shorts clamped to -1 as the specification says, and a stride too small refused.
TEST(GltfAccessors, StrideAndNormalizedIntegers) {
  GltfContext ctx("m.gltf");
  std::string bytes;
  put<int16_t>(bytes, {-32768, 32767, 7, 0, 0, -32767, 9, 0});  // two VEC2 shorts, 8-byte stride
  set_buffer(ctx, bytes, {{0, bytes.size()}});
  ctx.model.bufferViews[0].byteStride = 8;
  tinygltf::Accessor a = accessor(0, TINYGLTF_COMPONENT_TYPE_SHORT, 2, TINYGLTF_TYPE_VEC2);
  a.normalized = true;
  ctx.model.accessors.push_back(a);
  EXPECT_EQ(read_accessor_floats(ctx, 0, 2, "test"), (std::vector<float>{-1, 1, 0, -1}));
  ctx.model.bufferViews[0].byteStride = 2;
  expect_refused([&] { read_accessor_floats(ctx, 0, 2, "test"); },
                 "accessors[0] (test): byteStride 2 is smaller than an element",
                 "a stride smaller than an element was read");
}

// Found by review: sparse indices were read through floats, so an index past 2^24 moved
// (16,777,217 became 16,777,216: a triangle through it collapsed, with no warning); a float
// index type, which the specification forbids, was read too.
TEST(GltfAccessors, SparseIndicesAreReadAsIntegersAndOnlyUnsigned) {
  GltfContext ctx("m.gltf");
  std::string bytes;
  put<uint32_t>(bytes, {16777217, 3});  // the sparse indices, 8 bytes at 0
  put<float>(bytes, {5, 7});            // their values, 8 bytes at 8
  set_buffer(ctx, bytes, {{0, 8}, {8, 8}});
  // No bufferView: zeros, then the sparse values.
  tinygltf::Accessor a = accessor(-1, TINYGLTF_COMPONENT_TYPE_FLOAT, 16777218, TINYGLTF_TYPE_SCALAR);
  a.sparse.isSparse = true;
  a.sparse.count = 2;
  a.sparse.indices.bufferView = 0;
  a.sparse.indices.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  a.sparse.values.bufferView = 1;
  a.sparse.indices.byteOffset = a.sparse.values.byteOffset = 0;  // (tinygltf's parse sets them; its constructor not)
  ctx.model.accessors.push_back(a);
  const std::vector<float> v = read_accessor_floats(ctx, 0, 1, "test");
  ASSERT_EQ(v.size(), 16777218u);
  EXPECT_EQ(v[16777217], 5);
  EXPECT_EQ(v[16777216], 0);
  EXPECT_EQ(v[3], 7);
  ctx.model.accessors[0].sparse.indices.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  expect_refused([&] { read_accessor_floats(ctx, 0, 1, "test"); },
                 "sparse indices: must be unsigned byte, short or int", "float sparse indices were read");
}

// Found by review: an accessor's array was allocated at its declared count before its view
// was checked (a 452-byte file declaring 268 M vertices over 36 bytes took 3 GB before its
// refusal), and the count's bound ignored the components (a MAT4 accessor could ask for
// 16 GB, refused as std::bad_alloc). Both are refused now, naming the accessor.
TEST(GltfAccessors, DeclaredCountsAreCheckedBeforeAnythingIsAllocated) {
  GltfContext ctx("m.gltf");
  set_buffer(ctx, std::string(36, '\0'), {{0, 36}});
  // 960 MB of floats over a 36-byte view:
  tinygltf::Accessor a = accessor(0, TINYGLTF_COMPONENT_TYPE_FLOAT, 80'000'000, TINYGLTF_TYPE_VEC3);
  ctx.model.accessors.push_back(a);
  a.count = 268'435'455;  // 16 GB as a MAT4
  a.type = TINYGLTF_TYPE_MAT4;
  ctx.model.accessors.push_back(a);
  a.count = 0x5555555555555556;  // x 3 wraps to 2 in 64 bits: must not pass as 2 values
  a.type = TINYGLTF_TYPE_VEC3;
  ctx.model.accessors.push_back(a);
  const std::pair<int, const char*> cases[] = {
      {0, "accessors[0] (test): byteOffset 0 with 80000000 elements runs past the end of bufferView 0"},
      {1, "accessors[1] (test): count 268435455 x 16 components is over the limit of 268435456 values"},
      {2, "accessors[2] (test): count 6148914691236517206 x 3 components is over the limit"}};
  for (const auto& [index, reason] : cases) {
    expect_refused([&] { read_accessor_floats(ctx, index, index == 1 ? 16 : 3, "test"); }, reason,
                   "accessor " + std::to_string(index) + " was read");
  }
  // Indices have no value limit: their view's check must not wrap either (stride 2 x a
  // count near 2^63 is 0 in 64 bits).
  a.type = TINYGLTF_TYPE_SCALAR;
  a.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
  a.count = (uint64_t(1) << 63) + 1;
  ctx.model.accessors.push_back(a);
  expect_refused([&] { read_accessor_indices(ctx, 3, 3, "test"); }, "runs past the end of bufferView 0",
                 "indices past their view were read");
}

// Found by review: each texture index held its own decoded copy of its image, so one
// material naming one 4096^2 image through 13 textures held 13 copies (2.4 GB), and nothing
// bounded the texels of a scene. Textures of the same image, colour space and sampling
// are one texture, and every texture of an image (its colour spaces and samplers) shares
// its bytes; the images' texels are bounded together, the error naming the texture.
TEST(GltfTexturesShared, TheSameImageSampledTheSameWayIsDecodedOnceAndTheTexelsAreBounded) {
  GltfContext ctx("m.gltf");
  tinygltf::Image encoded;
  keep_image_encoded(&encoded, 0, nullptr, nullptr, 0, 0, kRedBluePng, int(sizeof kRedBluePng), nullptr);
  ctx.model.images = {encoded, encoded};  // two images, the same bytes: two sources
  tinygltf::Sampler clamp;
  clamp.wrapS = clamp.wrapT = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
  ctx.model.samplers = {clamp};
  auto texture = [](int source, int sampler) {
    tinygltf::Texture t;
    t.source = source;
    t.sampler = sampler;
    return t;
  };
  ctx.model.textures = {texture(0, -1), texture(0, -1), texture(0, 0), texture(1, -1)};
  GltfTextures textures(ctx);
  auto ref = [&](int index, bool srgb) {
    return textures.texture_ref(index, 0, {}, srgb, "materials[0]", "slot").index;
  };
  const int a = ref(0, true);
  EXPECT_EQ(ref(1, true), a);   // another texture, the same image and sampling: shared
  EXPECT_NE(ref(1, false), a);  // linear: its own copy
  EXPECT_NE(ref(2, true), a);   // clamped: its own
  ASSERT_EQ(ctx.scene.textures.size(), 3u);
  for (const Texture& t : ctx.scene.textures) {  // one image's bytes, 4 a texel, shared
    ASSERT_NE(t.rgba8, nullptr);
    EXPECT_EQ(t.rgba8, ctx.scene.textures[0].rgba8);
    EXPECT_EQ(t.rgba8->size(), 8u);
    EXPECT_TRUE(t.texels.empty());
  }
  // The image's 2 texels count once; another image's 2 would pass a limit of 3.
  ctx.max_scene_texels = 3;
  EXPECT_EQ(ref(0, false), ref(1, false));  // (shared textures cost nothing more)
  expect_refused([&] { ref(3, true); }, "textures[3]: the scene's textures would hold 4 texels, over the limit of 3",
                 "texels past the limit");
}

// Accessor 0 of the model: 3 VEC3 floats, (0, 0, 1) each, over buffer 0 (a morph target's).
void add_three_vec3s(GltfContext& ctx) {
  std::string bytes;
  put<float>(bytes, {0, 0, 1, 0, 0, 1, 0, 0, 1});
  set_buffer(ctx, bytes, {{0, bytes.size()}});
  ctx.model.accessors.push_back(accessor(0, TINYGLTF_COMPONENT_TYPE_FLOAT, 3, TINYGLTF_TYPE_VEC3));
}

// Found by review: morph targets were bounded per primitive, and a scene may hold a million
// mesh copies. The scene's targets are bounded together, the error naming the target.
TEST(GltfMorph, TheScenesTargetsAreBoundedTogether) {
  GltfContext ctx("m.gltf");
  add_three_vec3s(ctx);
  tinygltf::Primitive prim;
  prim.targets = {{{"POSITION", 0}}, {}, {{"POSITION", 0}}};  // the empty one costs nothing
  ctx.max_morph_values = 18;                                  // a target of 3 vertices holds 9
  ASSERT_EQ(read_gltf_morph(ctx, prim, tinygltf::Mesh(), tinygltf::Node(), 3, "first")->count(), 3u);
  // Another primitive (or another copy of this one) has no room left.
  expect_refused([&] { read_gltf_morph(ctx, prim, tinygltf::Mesh(), tinygltf::Node(), 3, "second"); },
                 "second targets[0]: the scene's morph targets would hold more than 18 values",
                 "morph targets past the scene's limit");
}

// The load-wide bound (GltfContext::max_load_bytes) counts every kind together: morph
// targets within their own limit are refused once the load's other kinds hold the rest,
// the error listing what each kind would hold.
TEST(GltfLoadBytes, EveryKindCountsTowardOneBound) {
  GltfContext ctx("m.gltf");
  add_three_vec3s(ctx);
  tinygltf::Primitive prim;
  prim.targets = {{{"POSITION", 0}}};  // 3 vertices: 36 bytes
  ctx.max_load_bytes = 100;
  ctx.charge("buffers", "buffers", 36);
  ctx.charge("images[0]", "textures", 8);
  ASSERT_NE(read_gltf_morph(ctx, prim, tinygltf::Mesh(), tinygltf::Node(), 3, "first"), nullptr);
  EXPECT_EQ(ctx.load_bytes(), 80u);
  expect_refused([&] { read_gltf_morph(ctx, prim, tinygltf::Mesh(), tinygltf::Node(), 3, "second"); },
                 "second targets[0]: the scene would take 116 bytes to load (buffers 36 bytes, morph targets 72 "
                 "bytes, textures 8 bytes), over the 100 bytes limit of a glTF load, all kinds together",
                 "a load past its memory bound");
}

}  // namespace
}  // namespace tessera
