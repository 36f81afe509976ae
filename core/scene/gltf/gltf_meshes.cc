#include "core/scene/gltf/gltf_meshes.h"

#include <algorithm>
#include <utility>

#include "core/scene/gltf/gltf_accessors.h"
#include "core/scene/gltf/gltf_skins.h"
#include "core/util/cancel.h"

namespace tessera {

namespace {

// A primitive's vertices as a list of triangles (glTF 2.0, 3.7.2.1: strip triangle i is
// {v[i], v[i + 1 + i % 2], v[i + 2 - i % 2]}, fan triangle i is {v[i + 1], v[i + 2], v[0]}).
std::vector<uint32_t> triangle_list(int mode, std::vector<uint32_t> v) {
  if (mode == TINYGLTF_MODE_TRIANGLES) return v;
  std::vector<uint32_t> out;
  if (v.size() < 3) return out;
  out.reserve((v.size() - 2) * 3);
  for (size_t i = 0; i + 2 < v.size(); ++i)
    if (mode == TINYGLTF_MODE_TRIANGLE_STRIP)
      out.insert(out.end(), {v[i], v[i + 1 + i % 2], v[i + 2 - i % 2]});
    else
      out.insert(out.end(), {v[i + 1], v[i + 2], v[0]});
  return out;
}

}  // namespace

std::vector<GltfPrimitive> read_gltf_mesh(GltfContext& ctx, GltfMaterials& materials, const tinygltf::Node& node,
                                          const Mat4& w, const std::string& node_el, bool keep_object_space) {
  const int index = node.mesh;
  if (size_t(index) >= ctx.model.meshes.size()) ctx.fail(node_el, "mesh " + std::to_string(index) + " does not exist");
  const tinygltf::Mesh& mesh = ctx.model.meshes[size_t(index)];
  // det < 0 mirrors the mesh: swap winding so geometric normals stay outward.
  const double det = w.det3();
  std::vector<GltfPrimitive> out;
  for (size_t p = 0; p < mesh.primitives.size(); ++p) {
    throw_if_cancelled();  // a scene check whose client went away
    const tinygltf::Primitive& prim = mesh.primitives[p];
    const std::string el = "meshes[" + std::to_string(index) + "].primitives[" + std::to_string(p) + "]";
    static const char* kModes[] = {"POINTS",    "LINES",          "LINE_LOOP",   "LINE_STRIP",
                                   "TRIANGLES", "TRIANGLE_STRIP", "TRIANGLE_FAN"};
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode > TINYGLTF_MODE_TRIANGLE_FAN) ctx.fail(el, "mode " + std::to_string(mode) + " is not a glTF mode (0-6)");
    if (mode < TINYGLTF_MODE_TRIANGLES) {
      ctx.warn_once(el + ": mode " + kModes[mode] + " has no surface to render: skipped");
      continue;
    }
    auto pos = prim.attributes.find("POSITION");
    if (pos == prim.attributes.end()) ctx.fail(el, "has no POSITION attribute");
    std::vector<float> p3 = read_accessor_floats(ctx, pos->second, 3, el + " POSITION");
    GltfPrimitive g;
    Mesh& m = g.mesh;
    m.name = mesh.name.empty() ? "mesh" + std::to_string(index) : mesh.name;
    const size_t nv = p3.size() / 3;
    g.morph = read_gltf_morph(ctx, prim, mesh, node, nv, el);
    if (node.skin >= 0) g.skin = read_gltf_skin(ctx, node.skin, prim, nv, el);
    std::vector<float> n3;  // the file's normals, object space
    if (auto nrm = prim.attributes.find("NORMAL"); nrm != prim.attributes.end()) {
      n3 = read_accessor_floats(ctx, nrm->second, 3, el + " NORMAL");
      if (n3.size() != p3.size()) ctx.fail(el, "NORMAL count differs from POSITION count");
    }
    // The shape shown, in object space: the file's, or moved by the morph targets' weights
    // (a skinned mesh is placed once its joints are known: add_gltf_nodes).
    std::vector<Vec3> morphed_p, morphed_n;
    if (g.morph && !g.skin) {
      morphed_p = as_vec3s(p3);
      morphed_n = as_vec3s(n3);
      apply_morph(*g.morph, g.morph->weights, morphed_p, morphed_n);
    }
    auto shown = [](const std::vector<Vec3>& morphed, const std::vector<float>& file, size_t i) {
      return morphed.empty() ? Vec3{file[3 * i], file[3 * i + 1], file[3 * i + 2]} : morphed[i];
    };
    m.positions.resize(nv);
    for (size_t i = 0; i < nv; ++i) {
      const Vec3 q = shown(morphed_p, p3, i);
      m.positions[i] = w.point(q.x, q.y, q.z).to_float();
      if (!is_finite(m.positions[i])) ctx.fail(el, "vertex " + std::to_string(i) + " is not finite after transform");
    }
    if (!n3.empty()) {
      const Mat4 nt = w.normal_matrix();
      m.normals.resize(nv);
      for (size_t i = 0; i < nv; ++i) {
        const Vec3 q = shown(morphed_n, n3, i);
        m.normals[i] = nt.unit_vector(q.x, q.y, q.z);
      }
      m.file_normals = true;
    } else {
      m.flat = true;  // "client implementations MUST calculate flat normals" (3.7.2.1)
    }
    if (prim.indices >= 0) {
      m.indices = read_accessor_indices(ctx, prim.indices, nv, el + " indices");
    } else {
      m.indices.resize(nv);
      for (size_t i = 0; i < nv; ++i) m.indices[i] = uint32_t(i);
    }
    m.indices = triangle_list(mode, std::move(m.indices));
    if (m.indices.size() % 3) ctx.fail(el, std::to_string(m.indices.size()) + " indices is not a multiple of 3");
    // A skinned mesh follows its joints, not the node: it keeps the file's winding.
    g.mirrored = det < 0 && !g.skin;
    if (g.mirrored)
      for (size_t t = 0; t < m.indices.size(); t += 3) std::swap(m.indices[t + 1], m.indices[t + 2]);
    if (auto c = prim.attributes.find("COLOR_0"); c != prim.attributes.end()) {
      // VEC3 or VEC4 (its alpha multiplies the material's: Scene::opacity_at).
      const int comps = c->second >= 0 && size_t(c->second) < ctx.model.accessors.size() &&
                                ctx.model.accessors[size_t(c->second)].type == TINYGLTF_TYPE_VEC4
                            ? 4
                            : 3;
      const std::vector<float> rgba = read_accessor_floats(ctx, c->second, comps, el + " COLOR_0");
      if (rgba.size() / size_t(comps) != nv) ctx.fail(el, "COLOR_0 count differs from POSITION count");
      m.colors.resize(nv);
      for (size_t i = 0; i < nv; ++i) {
        const float* v = &rgba[i * size_t(comps)];
        m.colors[i] = Rgb(std::clamp(v[0], 0.0f, 1.0f), std::clamp(v[1], 0.0f, 1.0f), std::clamp(v[2], 0.0f, 1.0f));
      }
      bool translucent = false;
      for (size_t i = 0; comps == 4 && i < nv; ++i) translucent |= !(rgba[i * 4 + 3] >= 1);
      if (translucent) {
        m.color_alpha.resize(nv);
        for (size_t i = 0; i < nv; ++i) m.color_alpha[i] = std::clamp(rgba[i * 4 + 3], 0.0f, 1.0f);
      }
    }
    if (auto uv = prim.attributes.find("TEXCOORD_0"); uv != prim.attributes.end()) {
      const std::vector<float> t2 = read_accessor_floats(ctx, uv->second, 2, el + " TEXCOORD_0");
      if (t2.size() / 2 != nv) ctx.fail(el, "TEXCOORD_0 count differs from POSITION count");
      m.uvs.resize(nv);
      for (size_t i = 0; i < nv; ++i) m.uvs[i] = {t2[2 * i], t2[2 * i + 1]};
    }
    if (auto uv = prim.attributes.find("TEXCOORD_1"); uv != prim.attributes.end()) {
      const std::vector<float> t2 = read_accessor_floats(ctx, uv->second, 2, el + " TEXCOORD_1");
      if (t2.size() / 2 != nv) ctx.fail(el, "TEXCOORD_1 count differs from POSITION count");
      m.uvs1.resize(nv);
      for (size_t i = 0; i < nv; ++i) m.uvs1[i] = {t2[2 * i], t2[2 * i + 1]};
    }
    m.material = materials.material(prim.material);
    const Material& mat = ctx.scene.materials[m.material];
    for (const TextureRef* t :
         {&mat.texture, &mat.metal_rough_texture, &mat.normal_texture, &mat.emissive_texture, &mat.transmission_texture,
          &mat.specular_texture, &mat.specular_color_texture, &mat.clearcoat_texture, &mat.clearcoat_roughness_texture,
          &mat.clearcoat_normal_texture, &mat.sheen_color_texture, &mat.sheen_roughness_texture})
      if (t->active() && t->set == 1 && m.uvs1.empty())
        ctx.warn_once(el + ": its material reads TEXCOORD_1, which it lacks; TEXCOORD_0 is used");
    // TANGENT, object space: only where a normal map reads it, the base's or the coat's (a
    // skinned mesh's joints would have to carry it too: it takes the triangle's frame), and
    // not without NORMAL ("the provided tangents MUST be ignored", 3.7.2.1).
    std::vector<float> t4;
    const bool mapped = mat.normal_texture.active() || mat.clearcoat_normal_texture.active();
    if (auto tan = prim.attributes.find("TANGENT"); tan != prim.attributes.end() && mapped && !g.skin && !m.flat) {
      t4 = read_accessor_floats(ctx, tan->second, 4, el + " TANGENT");
      if (t4.size() / 4 != nv) ctx.fail(el, "TANGENT count differs from POSITION count");
      // A direction (transformed as an edge is); the bitangent's sign turns with a mirror.
      m.tangents.resize(nv);
      for (size_t i = 0; i < nv; ++i) {
        m.tangents[i].t = w.unit_vector(t4[4 * i], t4[4 * i + 1], t4[4 * i + 2]);
        m.tangents[i].sign = (t4[4 * i + 3] < 0) != (det < 0) ? -1.0f : 1.0f;
      }
    }
    if (m.indices.empty()) continue;
    if (keep_object_space || g.skin) {
      g.positions = std::move(p3);
      g.normals = std::move(n3);
      g.tangents = std::move(t4);
    }
    out.push_back(std::move(g));
  }
  return out;
}

}  // namespace tessera
