#include "core/scene/collada/collada_loader.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <pugixml.hpp>
#include <set>
#include <sstream>
#include <unordered_map>

#include "core/math/transform.h"
#include "core/scene/collada/xml_text.h"
#include "core/scene/scene_error.h"
#include "core/util/cancel.h"

namespace tessera {
namespace {

class ColladaLoader {
 public:
  ColladaLoader(const std::string& text, std::string name, uint64_t max_triangles)
      : text_(text), xml_(text, std::move(name)), file_(xml_.file()), max_triangles_(max_triangles) {}

  Scene load() {
    scene_.source = file_;
    pugi::xml_parse_result res = doc_.load_buffer(text_.data(), text_.size(), pugi::parse_default);
    if (!res)
      throw SceneError(file_, "line " + std::to_string(xml_.line_of(res.offset)),
                       std::string("XML parse error: ") + res.description());
    pugi::xml_node root = doc_.child("COLLADA");
    if (!root) throw SceneError(file_, "", "not a COLLADA document (no <COLLADA> root element)");
    for (const pugi::xpath_node& n : root.select_nodes("//*[@id]"))
      ids_.emplace(n.node().attribute("id").value(), n.node());  // first definition wins
    global_ = up_axis_transform(root);
    pugi::xml_node inst = root.child("scene").child("instance_visual_scene");
    if (!inst) throw SceneError(file_, where(root), "no <scene>/<instance_visual_scene>");
    pugi::xml_node vs = resolve(inst, "url", "visual_scene");
    for (pugi::xml_node node : vs.children("node")) process_node(node, global_, 0);
    if (scene_.meshes.empty() && scene_.spheres.empty()) {  // refused, as by glTF's loader, naming what was skipped
      std::string why = "no meshes or spheres to render";
      for (const auto& [what, ignored] : ignored_) why += "; skipped: " + what;
      fail(vs, why);
    }
    for (const auto& [what, ignored] : ignored_)
      scene_.warnings.push_back(
          ignored.first + ": " + what +
          (ignored.count > 1 ? " (and " + std::to_string(ignored.count - 1) + " more like it)" : ""));
    scene_.finalize();
    return std::move(scene_);
  }

 private:
  // ---- diagnostics and numbers (xml_text.h) -----------------------------------------
  std::string where(pugi::xml_node n) const { return xml_.where(n); }
  [[noreturn]] void fail(pugi::xml_node n, const std::string& reason) const { xml_.fail(n, reason); }
  std::vector<double> numbers(pugi::xml_node n) const { return xml_.numbers(n); }
  std::vector<double> numbers_exact(pugi::xml_node n, size_t want) const { return xml_.numbers_exact(n, want); }
  std::vector<uint32_t> indices(pugi::xml_node n) const { return xml_.indices(n); }
  static std::string short_number(double v) { return XmlText::short_number(v); }

  // A colour in [0, hi] per channel: reflectances in [0, 1] (above 1 a surface creates
  // energy, and a hostile 3e38 overflowed a pixel's sums). Emitted colours are checked by
  // Scene::finalize (kMaxEmission) for both loaders.
  Rgb color(pugi::xml_node parent, const char* child, double hi = HUGE_VAL) const {
    pugi::xml_node c = parent.child(child);
    if (!c) fail(parent, std::string("missing <") + child + ">");
    const std::vector<double> v = numbers_exact(c, 3);
    for (double x : v)
      if (hi < HUGE_VAL && !(x >= 0 && x <= hi))
        fail(c,
             "<" + std::string(child) + "> component " + short_number(x) + " is outside [0, " + short_number(hi) + "]");
    return Rgb(float(v[0]), float(v[1]), float(v[2]));
  }
  // A scalar in (lo, hi].
  double scalar_in(pugi::xml_node parent, const char* child, double lo, double hi) const {
    const double v = scalar(parent, child);
    if (!(v > lo && v <= hi))
      fail(parent.child(child), "<" + std::string(child) + "> " + short_number(v) + " is outside (" + short_number(lo) +
                                    ", " + short_number(hi) + "]");
    return v;
  }
  double scalar(pugi::xml_node parent, const char* child, std::optional<double> fallback = {}) const {
    pugi::xml_node c = parent.child(child);
    if (!c) {
      if (fallback) return *fallback;
      fail(parent, std::string("missing <") + child + ">");
    }
    return numbers_exact(c, 1)[0];
  }
  pugi::xml_node resolve(pugi::xml_node from, const char* attr, const char* expect) const {
    std::string url = from.attribute(attr).value();
    if (url.empty()) fail(from, std::string("missing ") + attr + " attribute");
    if (url[0] != '#') fail(from, "only local references (#id) are supported, got '" + url + "'");
    auto it = ids_.find(url.substr(1));
    if (it == ids_.end()) fail(from, "dangling reference '" + url + "'");
    if (expect && std::string(it->second.name()) != expect)
      fail(from, "'" + url + "' names a <" + it->second.name() + ">, expected <" + expect + ">");
    return it->second;
  }

  // ---- document structure ------------------------------------------------------------
  Mat4 up_axis_transform(pugi::xml_node root) const {
    pugi::xml_node up = root.child("asset").child("up_axis");
    if (!up) return Mat4();  // COLLADA's default is Y_UP
    std::string s = up.child_value();
    s.erase(std::remove_if(s.begin(), s.end(), [](char c) { return std::isspace(uint8_t(c)); }), s.end());
    if (s == "Y_UP") return Mat4();
    if (s == "Z_UP")  // (x, y, z) -> (-x, z, y): a proper rotation
      return Mat4::from_row_major({-1, 0, 0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 1});
    if (s == "X_UP")  // (x, y, z) -> (y, x, -z)
      return Mat4::from_row_major({0, 1, 0, 0, 1, 0, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1});
    fail(up, "unknown up_axis '" + s + "' (expected X_UP, Y_UP or Z_UP)");
  }

  Mat4 local_transform(pugi::xml_node node) const {
    Mat4 local;
    for (pugi::xml_node e : node.children()) {
      const std::string name = e.name();
      if (name == "matrix") {
        // Replaces what came before and ends the node's transform list (format doc 1.5);
        // a short matrix reads its missing entries as 0.
        std::vector<double> v = numbers(e);
        if (v.size() > 16) fail(e, "more than 16 numbers in <matrix>");
        std::array<double, 16> m{};
        std::copy(v.begin(), v.end(), m.begin());
        return Mat4::from_row_major(m);
      }
      if (name == "translate") {
        auto v = numbers_exact(e, 3);
        local = local * Mat4::translate(v[0], v[1], v[2]);
      } else if (name == "scale") {
        auto v = numbers_exact(e, 3);
        local = local * Mat4::scale(v[0], v[1], v[2]);
      } else if (name == "rotate") {
        auto v = numbers_exact(e, 4);
        local = local * Mat4::rotate(v[0], v[1], v[2], v[3]);
      }
    }
    return local;
  }

  void process_node(pugi::xml_node node, const Mat4& parent, int depth) {
    throw_if_cancelled();
    if (depth > 256) fail(node, "node hierarchy deeper than 256 levels");
    const Mat4 world = parent * local_transform(node);
    for (pugi::xml_node child : node.children("node")) process_node(child, world, depth + 1);
    pugi::xml_node used;
    if (pugi::xml_node c = node.child("instance_camera")) {
      add_camera(resolve(c, "url", "camera"), world);
      used = c;
    } else if (pugi::xml_node l = node.child("instance_light")) {
      add_light(resolve(l, "url", "light"), world, node);
      used = l;
    } else if (pugi::xml_node g = node.child("instance_geometry")) {
      add_geometry(resolve(g, "url", "geometry"), g, world, node);
      used = g;
    }
    // A node without instances is a pure group: legal COLLADA, nothing to add.
    // What CS184's reader skips is skipped here too, but said (once a kind, with a count).
    for (pugi::xml_node e : node.children()) {
      const std::string name = e.name();
      if (name.rfind("instance_", 0) == 0 && e != used)  // (other names as one kind: one warning, not one each)
        ignore(e, "<" + (kInstances.count(name) ? name : std::string("instance_...")) +
                      "> not used: a node yields one object, its first camera, else light, else geometry (CS184's "
                      "rule)");
      else if (name == "lookat" || name == "skew")
        ignore(e, "<" + name + "> is not supported (ignored, as CS184 ignores it)");
    }
  }

  inline static const std::set<std::string> kInstances = {"instance_camera", "instance_controller", "instance_geometry",
                                                          "instance_light", "instance_node"};
  // Something of the file skipped: one warning a kind, naming where it was first met.
  void ignore(pugi::xml_node n, const std::string& what) {
    Ignored& i = ignored_[what];
    if (i.count++ == 0) i.first = where(n);
  }
  struct Ignored {
    std::string first;
    size_t count = 0;
  };
  std::map<std::string, Ignored> ignored_;

  // ---- cameras -----------------------------------------------------------------------
  void add_camera(pugi::xml_node cam, const Mat4& w) {
    pugi::xml_node tc = cam.child("optics").child("technique_common");
    if (tc.child("orthographic")) fail(cam, "orthographic cameras are not supported");
    pugi::xml_node p = tc.child("perspective");
    if (!p) fail(cam, "missing <optics>/<technique_common>/<perspective>");
    CameraDesc& c = scene_.camera;
    c = CameraDesc{};
    c.present = true;
    c.xfov_deg = scalar(p, "xfov", 50.0);
    if (p.child("yfov")) c.yfov_deg = scalar(p, "yfov");
    if (p.child("aspect_ratio")) c.aspect_ratio = scalar(p, "aspect_ratio");
    c.znear = float(scalar(p, "znear", 0.001));
    c.zfar = float(scalar(p, "zfar", 1000.0));
    if (!(c.xfov_deg > 0 && c.xfov_deg < 180)) fail(p, "xfov must be in (0, 180) degrees");
    if (c.yfov_deg && !(*c.yfov_deg > 0 && *c.yfov_deg < 180)) fail(p, "yfov must be in (0, 180) degrees");
    // (A tiny ratio made the view's tangent infinite: NaN rays, which Embree aborts on.)
    if (c.aspect_ratio && !(*c.aspect_ratio >= 1e-4 && *c.aspect_ratio <= 1e4))
      fail(p, "aspect_ratio " + short_number(*c.aspect_ratio) + " is outside [0.0001, 10000]");
    if (!c.yfov_deg && !c.aspect_ratio) {
      c.aspect_ratio = 4.0 / 3.0;
      ignore(cam, "no yfov or aspect_ratio; assuming 4:3");
    }
    c.eye = w.point(0, 0, 0).to_float();
    // Unit directions in double where float's squares overflow (a node scaled by 1e20 gave a
    // zero direction that passed as finite).
    c.forward = unit(w.vector(0, 0, -1));
    c.up = unit(w.vector(0, 1, 0));
    // CS184 treats the point one unit ahead as a direction (format doc 2.2, a w=1 quirk).
    c.cs184_dir = unit(w.apply(0, 0, -1, 1));
    if (c.cs184_dir == Vec3{}) fail(cam, "camera node transform is degenerate");
    // The pose and clip planes serve only --camera file; CS184's framing (the default for
    // these files) never reads them, and neither does the course's renderer: a malformed
    // one is a warning here and an error only for a render that uses it.
    if (!(c.znear >= 0 && c.zfar > c.znear))
      c.pose_problem = where(p) + ": need 0 <= znear < zfar";
    else if (!is_finite(c.eye) || !is_finite(c.forward) || !is_finite(c.up) || length(cross(c.forward, c.up)) < 1e-6f)
      c.pose_problem = where(cam) + ": camera node transform is degenerate";
    else if (!(max_component(abs(c.eye)) <= Scene::kMaxCoordinate))
      c.pose_problem = where(cam) + ": eye outside +-1e12";
    if (!c.pose_problem.empty()) {
      c.eye = {};  // (unused: --camera file refuses the pose)
      ignore(cam, c.pose_problem.substr(c.pose_problem.find(": ") + 2) +
                      "; CS184 framing does not use it (--camera file would)");
    }
  }

  // ---- lights ------------------------------------------------------------------------
  void add_light(pugi::xml_node light, const Mat4& w, pugi::xml_node node) {
    pugi::xml_node tech;
    if (pugi::xml_node extra = light.child("extra"))
      tech = extra.find_child_by_attribute("technique", "profile", "CGL");
    if (!tech) tech = light.child("technique_common");
    if (!tech) fail(light, "no <technique_common> or CGL technique");
    pugi::xml_node type = tech.first_child();
    while (type && type.type() != pugi::node_element) type = type.next_sibling();
    if (!type) fail(tech, "empty light technique");
    const std::string kind = type.name();
    Light l;
    l.name = node.attribute("id").value();
    if (kind == "spot") return ignore(type, "spot lights are not supported; ignored");
    l.color = color(type, "color");
    if (kind == "point") {
      l.kind = Light::Kind::kPoint;
      l.position = w.point(0, 0, 0).to_float();
      l.att_constant = float(scalar(type, "constant_attenuation", 1.0));
      l.att_linear = float(scalar(type, "linear_attenuation", 0.0));
      l.att_quadratic = float(scalar(type, "quadratic_attenuation", 0.0));
      if (l.att_constant < 0 || l.att_linear < 0 || l.att_quadratic < 0 ||
          l.att_constant + l.att_linear + l.att_quadratic <= 0)
        fail(type, "attenuation coefficients must be non-negative and not all zero");
    } else if (kind == "directional") {
      l.kind = Light::Kind::kDirectional;
      l.direction = -unit(w.vector(0, 0, -1));
      if (l.direction == Vec3{}) fail(node, "directional light's transform is degenerate");
    } else if (kind == "ambient") {
      l.kind = Light::Kind::kAmbient;
    } else if (kind == "area") {
      l.kind = Light::Kind::kRect;
      l.position = w.point(0, 0, 0).to_float();
      l.edge_x = w.vector(-1, 0, 0).to_float();
      l.edge_y = w.vector(0, 1, 0).to_float();
      const Vec3 facing = w.vector(0, 0, -1).to_float();
      const Vec3 c = cross(l.edge_x, l.edge_y);
      l.area = length(c);
      Vec3 n = c / l.area;
      if (!(l.area > 1e-18f && l.area < 1e18f)) {  // where float's squares overflow or underflow: in double
        const Dvec3 cd = dcross(w.vector(-1, 0, 0), w.vector(0, 1, 0));
        l.area = float(dlength(cd));  // (a light 1e11 across was refused as of "zero area")
        n = unit(cd);
      }
      if (!(l.area > 0) || !std::isfinite(l.area) || n == Vec3{}) fail(node, "area light has zero area");
      l.normal = face_forward(n, facing);
    } else {
      fail(type, "unknown light type <" + kind + ">");
    }
    if (!is_finite(l.position) || !is_finite(l.direction)) fail(node, "light transform is degenerate");
    scene_.lights.push_back(l);
  }

  // ---- materials ---------------------------------------------------------------------
  uint32_t material_for(pugi::xml_node instance_geometry) {
    pugi::xml_node im = instance_geometry.child("bind_material").child("technique_common").child("instance_material");
    if (!im) return default_material();
    pugi::xml_node mat = resolve(im, "target", "material");
    const std::string id = mat.attribute("id").value();
    if (auto it = materials_.find(id); it != materials_.end()) return it->second;
    pugi::xml_node ie = mat.child("instance_effect");
    if (!ie) fail(mat, "missing <instance_effect>");
    Material m = parse_effect(resolve(ie, "url", "effect"));
    m.name = id;
    const uint32_t index = scene_.add_material(std::move(m));
    materials_[id] = index;
    return index;
  }
  uint32_t default_material() {
    if (!default_material_) {
      Material m;
      m.name = "default-gray";
      default_material_ = scene_.add_material(m);
    }
    return *default_material_;
  }
  Material parse_effect(pugi::xml_node effect) {
    Material m;
    pugi::xml_node cgl;
    for (pugi::xml_node extra : effect.children("extra"))
      if ((cgl = extra.find_child_by_attribute("technique", "profile", "CGL"))) break;
    if (cgl) {
      bool found = false;
      for (pugi::xml_node k : cgl.children()) {
        if (k.type() != pugi::node_element) continue;
        const std::string kind = k.name();
        m = Material{};
        if (kind == "mirror") {
          m.kind = Material::Kind::kMirror;
          m.reflectance = color(k, "reflectance", 1);
        } else if (kind == "glass") {
          m.kind = Material::Kind::kGlass;
          m.reflectance = color(k, "reflectance", 1);
          m.transmittance = color(k, "transmittance", 1);
          m.ior = float(scalar_in(k, "ior", 1e-3, 10));
        } else if (kind == "refraction") {
          m.kind = Material::Kind::kRefraction;
          m.transmittance = color(k, "transmittance", 1);
          m.ior = float(scalar_in(k, "ior", 1e-3, 10));
        } else if (kind == "microfacet") {
          m.kind = Material::Kind::kMicrofacet;
          m.alpha = float(scalar_in(k, "alpha", 1e-4, 10));  // (alpha^2 in float: under about 1e-19 it is 0)
          m.eta = color(k, "eta", 100);
          m.k = color(k, "k", 100);
        } else if (kind == "emission") {
          m.kind = Material::Kind::kEmission;
          m.radiance = color(k, "radiance");
        } else {
          fail(k, "unknown CGL material kind <" + kind + ">");
        }
        found = true;  // the last recognised kind wins (format doc 4.2)
      }
      if (!found) fail(cgl, "CGL technique names no material kind");
      return m;
    }
    pugi::xml_node tech = effect.child("profile_COMMON").child("technique");
    for (const char* shading : {"phong", "lambert", "blinn"}) {
      pugi::xml_node s = tech.child(shading);
      if (s && s.child("diffuse").child("color")) {
        m.kind = Material::Kind::kDiffuse;
        m.reflectance = color(s.child("diffuse"), "color", 1);
        return m;
      }
    }
    return m;  // 0.5 gray diffuse
  }

  // ---- geometry ----------------------------------------------------------------------
  void add_geometry(pugi::xml_node geom, pugi::xml_node instance, const Mat4& w, pugi::xml_node node) {
    const uint32_t material = material_for(instance);
    const std::string name = node.attribute("id").value();
    if (pugi::xml_node mesh = geom.child("mesh")) {
      add_mesh(mesh, w, material, node);
      return;
    }
    pugi::xml_node sphere;
    for (pugi::xml_node extra : geom.children("extra"))
      if (pugi::xml_node t = extra.find_child_by_attribute("technique", "profile", "CGL"))
        if ((sphere = t.child("sphere"))) break;
    if (!sphere) fail(geom, "geometry has neither a <mesh> nor a CGL <sphere>");
    const double r = scalar(sphere, "radius");
    if (!(r > 0)) fail(sphere, "sphere radius must be positive");
    Sphere s;
    s.name = name;
    s.center = w.point(0, 0, 0).to_float();
    s.radius = float(r * dlength(w.vector(1, 0, 0)));
    s.material = material;
    if (!is_finite(s.center) || !(s.radius > 0) || !std::isfinite(s.radius))
      fail(node, "sphere transform is degenerate");
    scene_.spheres.push_back(s);
  }

  std::vector<double> float_array(pugi::xml_node source) const {
    pugi::xml_node fa = source.child("float_array");
    if (!fa) fail(source, "source has no <float_array>");
    const uint64_t count = xml_.whole_attribute(fa, "count", UINT64_MAX);
    std::vector<double> v = numbers(fa);
    if (v.size() != size_t(count))
      fail(fa, "count=\"" + std::to_string(count) + "\" but " + std::to_string(v.size()) + " numbers present");
    return v;
  }

  // A geometry's <mesh> placed by a node: parsed once however many nodes place it (each
  // placement a copy, in world space), within the scene's triangle budget.
  void add_mesh(pugi::xml_node mesh, const Mat4& w, uint32_t material, pugi::xml_node node) {
    const ParsedMesh& m = parsed(mesh);
    const std::string name = node.attribute("id").value();
    // Triangles and vertices: a copy holds both (a mesh of a million vertices and one
    // triangle, placed 100,000 times, would be 10^11 vertices).
    const uint64_t triangles = m.indices.size() / 3, vertices = m.positions.size() / 3;
    if (triangles_ + triangles > max_triangles_ || vertices_ + vertices > max_triangles_)
      fail(node, "the scene's nodes place more than " + std::to_string(max_triangles_) +
                     " triangles or vertices, the limit (each <instance_geometry> is a copy of its mesh)");
    triangles_ += triangles;
    vertices_ += vertices;
    Mesh out;
    out.name = name;
    out.material = material;
    out.positions.reserve(m.positions.size() / 3);
    for (size_t i = 0; i < m.positions.size(); i += 3) {
      const Vec3 v = w.point(m.positions[i], m.positions[i + 1], m.positions[i + 2]).to_float();
      if (!is_finite(v)) fail(m.vertices, "vertex " + std::to_string(i / 3) + " is not finite after transform");
      out.positions.push_back(v);
    }
    out.indices = m.indices;
    scene_.meshes.push_back(std::move(out));
  }

  // A <mesh> read: its positions in its own space, its polygons fanned into triangles.
  struct ParsedMesh {
    pugi::xml_node vertices;
    std::vector<double> positions;  // 3 a vertex
    std::vector<uint32_t> indices;  // 3 a triangle
  };
  const ParsedMesh& parsed(pugi::xml_node mesh) {
    auto [it, added] = parsed_.try_emplace(mesh.internal_object());
    if (added) {
      try {
        it->second = parse_mesh(mesh);
      } catch (...) {
        parsed_.erase(it);
        throw;
      }
    }
    return it->second;
  }
  ParsedMesh parse_mesh(pugi::xml_node mesh) {
    pugi::xml_node vertices = mesh.child("vertices");
    if (!vertices) fail(mesh, "mesh has no <vertices>");
    pugi::xml_node pos_input = vertices.find_child_by_attribute("input", "semantic", "POSITION");
    if (!pos_input) fail(vertices, "no POSITION input");
    ParsedMesh out;
    out.vertices = vertices;
    out.positions = float_array(resolve(pos_input, "source", "source"));
    const std::vector<double>& p = out.positions;
    if (p.size() % 3) fail(vertices, "position count " + std::to_string(p.size()) + " is not a multiple of 3");
    if (p.size() / 3 > UINT32_MAX) fail(vertices, "more than 2^32 vertices");
    const uint32_t vertex_count = uint32_t(p.size() / 3);
    bool any = false;
    for (pugi::xml_node prim : mesh.children()) {
      const std::string kind = prim.name();
      if (kind == "lines" || kind == "linestrips" || kind == "tristrips" || kind == "trifans")
        ignore(prim, "<" + kind + "> is not supported (only <triangles>, <polylist> and <polygons> are read)");
      if (kind != "polylist" && kind != "triangles" && kind != "polygons") continue;
      any = true;
      uint32_t stride = 0, vertex_offset = 0;
      bool has_vertex = false;
      for (pugi::xml_node in : prim.children("input")) {
        const uint64_t off = xml_.whole_attribute(in, "offset", 64);
        stride = std::max(stride, uint32_t(off) + 1);
        if (std::string(in.attribute("semantic").value()) == "VERTEX") {
          if (resolve(in, "source", nullptr) != vertices) fail(in, "VERTEX source is not the mesh's <vertices>");
          vertex_offset = uint32_t(off);
          has_vertex = true;
        }
      }
      if (!has_vertex) fail(prim, "no VERTEX input");
      const uint64_t count = xml_.whole_attribute(prim, "count", UINT64_MAX);
      std::vector<uint32_t> sizes, idx;
      if (kind == "polygons") {
        for (pugi::xml_node pp : prim.children("p")) {
          std::vector<uint32_t> one = indices(pp);
          if (one.size() % stride) fail(pp, "index count is not a multiple of the input stride");
          sizes.push_back(uint32_t(one.size() / stride));
          idx.insert(idx.end(), one.begin(), one.end());
        }
      } else {
        pugi::xml_node pn = prim.child("p");
        if (!pn && count > 0) fail(prim, "missing <p>");
        idx = indices(pn);
        if (kind == "polylist") {
          pugi::xml_node vc = prim.child("vcount");
          if (!vc) fail(prim, "missing <vcount>");
          sizes = indices(vc);
        } else {
          sizes.assign(size_t(std::min<uint64_t>(count, idx.size() / (3 * uint64_t(stride)))), 3);
        }
      }
      if (sizes.size() != size_t(count))
        fail(prim, "count=\"" + std::to_string(count) + "\" but " + std::to_string(sizes.size()) + " polygons present");
      uint64_t need = 0;
      for (uint32_t s : sizes) {
        if (s < 3) fail(prim, "polygon with " + std::to_string(s) + " vertices");
        // Saturating: <vcount>s summing past 2^64 must not wrap to <p>'s size (the fan below
        // would read past it). (s x stride < 2^39.)
        const uint64_t more = uint64_t(s) * stride;
        need = need > UINT64_MAX - more ? UINT64_MAX : need + more;
      }
      if (need != idx.size())
        fail(prim, "expected " + std::to_string(need) + " indices in <p>, found " + std::to_string(idx.size()));
      size_t at = 0;
      for (uint32_t s : sizes) {
        auto vert = [&](uint32_t k) {
          const uint32_t v = idx[at + size_t(k) * stride + vertex_offset];
          if (v >= vertex_count)
            fail(prim, "vertex index " + std::to_string(v) + " out of range (" + std::to_string(vertex_count) +
                           " positions)");
          return v;
        };
        for (uint32_t k = 1; k + 1 < s; ++k) {  // fan triangulation
          out.indices.push_back(vert(0));
          out.indices.push_back(vert(k));
          out.indices.push_back(vert(k + 1));
        }
        at += size_t(s) * stride;
      }
    }
    if (!any) fail(mesh, "mesh has no <polylist>, <triangles> or <polygons>");
    return out;
  }

  const std::string& text_;
  XmlText xml_;
  const std::string& file_;
  pugi::xml_document doc_;
  std::unordered_map<std::string, pugi::xml_node> ids_;
  std::unordered_map<std::string, uint32_t> materials_;
  std::optional<uint32_t> default_material_;
  Mat4 global_;
  Scene scene_;
  std::unordered_map<pugi::xml_node_struct*, ParsedMesh> parsed_;
  uint64_t max_triangles_;
  uint64_t triangles_ = 0, vertices_ = 0;  // placed so far
};

}  // namespace

Scene load_collada_string(const std::string& text, const std::string& name, uint64_t max_triangles) {
  return ColladaLoader(text, name, max_triangles).load();
}

Scene load_collada_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, "", "cannot open file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return load_collada_string(ss.str(), path);
}

}  // namespace tessera
