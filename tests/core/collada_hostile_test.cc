// The COLLADA loader against what an audit (2026-11-29) found it took badly: files that
// aborted the process inside Embree (a camera it could not place, a direction scaled past
// float's squares, a view with an infinite tangent), values whose float narrowing made
// every sample NaN, comments that cut a list of numbers short, warnings that made loading
// take time growing with the square of the file's size, and errors that misnamed the
// problem. Each scene here is small and written in place.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include "core/camera/camera.h"
#include "core/render/settings.h"
#include "core/scene/collada/collada_loader.h"
#include "core/scene/collada/xml_text.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

// A COLLADA document: `library` elements (lights, cameras, effects...) and the visual
// scene's nodes, with one diffuse triangle unless `nodes` places its own geometry.
std::string document(const std::string& library, const std::string& nodes,
                     const std::string& triangle_node = R"(<node id="tri"><instance_geometry url="#g"/></node>)") {
  return R"(<?xml version="1.0"?><COLLADA><asset><up_axis>Y_UP</up_axis></asset>)" + library +
         R"(<library_geometries><geometry id="g"><mesh>
<source id="p"><float_array id="pa" count="9">-1 -1 0 1 -1 0 0 1 0</float_array></source>
<vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
<triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
</mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s">)" +
         triangle_node + nodes + R"(</visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#s"/></scene></COLLADA>)";
}

std::string error_of(const std::string& text) {
  try {
    load_collada_string(text, "bad.dae");
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

std::string camera_error(const Scene& scene, Framing framing = Framing::kCs184) {
  CameraSettings cs;
  cs.width = 32;
  cs.height = 24;
  cs.framing = framing;
  try {
    Camera camera(scene, cs);
  } catch (const SettingsError& e) {
    return e.what();
  }
  return "";
}

const std::string kCamera = R"(<library_cameras><camera id="c"><optics><technique_common><perspective>
<xfov>45</xfov><aspect_ratio>ASPECT</aspect_ratio><znear>0.1</znear><zfar>100</zfar>
</perspective></technique_common></optics></camera></library_cameras>)";

std::string with(std::string s, const std::string& from, const std::string& to) {
  return s.replace(s.find(from), from.size(), to);
}

// The camera is placed, or refused naming why: never a camera of NaN rays (Embree's
// assertion aborted the process on the first one).
TEST(ColladaHostile, ACameraItCannotPlaceIsRefusedNotTraced) {
  // All three vertices at one point: a scene one point big is framed as an empty one.
  const std::string point = with(document("", ""), "-1 -1 0 1 -1 0 0 1 0", "1 1 1 1 1 1 1 1 1");
  EXPECT_EQ(camera_error(load_collada_string(point, "point.dae")), "");
  // A unit triangle at 1e11: float holds no step of a few units there.
  const Scene far = load_collada_string(
      document("", "",
               R"(<node><matrix>1 0 0 0 0 1 0 0 0 0 1 1e11 0 0 0 1</matrix><instance_geometry url="#g"/></node>)"),
      "far.dae");
  EXPECT_NE(camera_error(far).find("CS184 framing cannot place the camera"), std::string::npos) << camera_error(far);
  // A view whose tangent is not finite: refused at load (the ratio), and by the camera
  // whatever made it.
  EXPECT_NE(error_of(document(with(kCamera, "ASPECT", "1e-40"), R"(<node><instance_camera url="#c"/></node>)"))
                .find("aspect_ratio 1e-40 is outside [0.0001, 10000]"),
            std::string::npos);
  Scene wide = load_collada_string(
      document(with(kCamera, "ASPECT", "1.5"), R"(<node><instance_camera url="#c"/></node>)"), "wide.dae");
  wide.camera.aspect_ratio = 1e-300;  // (as another loader could leave it)
  EXPECT_NE(camera_error(wide, Framing::kFile).find("the camera is degenerate"), std::string::npos)
      << camera_error(wide, Framing::kFile);
}

// Directions from nodes scaled past 1e19: float's squared length overflowed and the
// "unit" direction came out (0, 0, 0), finite, so it passed; now they are made unit in
// double.
TEST(ColladaHostile, DirectionsOfHugelyScaledNodesStayUnit) {
  const std::string scale = "<matrix>1e20 0 0 0 0 1e20 0 0 0 0 1e20 0 0 0 0 1</matrix>";
  const Scene s =
      load_collada_string(document(R"(<library_lights><light id="d"><technique_common><directional><color>1 1 1</color>
</directional></technique_common></light></library_lights>)" +
                                       with(kCamera, "ASPECT", "1.5"),
                                   "<node>" + scale + R"(<instance_light url="#d"/></node><node>)" + scale +
                                       R"(<instance_camera url="#c"/></node>)"),
                          "scaled.dae");
  ASSERT_EQ(s.lights.size(), 1u);
  EXPECT_NEAR(length(s.lights[0].direction), 1, 1e-6);
  EXPECT_NEAR(s.lights[0].direction.z, 1, 1e-6);
  EXPECT_NEAR(length(s.camera.cs184_dir), 1, 1e-6);
  EXPECT_EQ(camera_error(s), "");
}

// Found by audit: an area light's area was a float cross product, whose squares overflow
// past about 1e19 (a scene scaled by 1e11, inside the 1e12 allowed, was refused as "zero
// area") and underflow below about 1e-19. In double there.
TEST(ColladaHostile, AreaLightsFloatsSquaresCannotHoldAreMeasuredInDouble) {
  const std::string area = R"(<library_lights><light id="a"><technique_common><point><color>1 1 1</color></point>
</technique_common><extra><technique profile="CGL"><area><color>1 1 1</color></area></technique></extra></light>
</library_lights>)";
  for (const double k : {1e11, 1e-11}) {
    std::ostringstream m;
    m << "<matrix>" << 0.6 * k << " 0 0 0 0 " << 0.8 * k << " 0 " << k << " 0 0 " << k << " 0 0 0 0 1</matrix>";
    const Scene s = load_collada_string(
        document(area, "<node id=\"L\">" + m.str() + R"(<instance_light url="#a"/></node>)"), "big.dae");
    ASSERT_EQ(s.lights.size(), 1u);
    EXPECT_NEAR(s.lights[0].area / (0.48 * k * k), 1, 1e-6) << k;
    EXPECT_NEAR(length(s.lights[0].normal), 1, 1e-6) << k;
    EXPECT_NEAR(std::fabs(s.lights[0].normal.z), 1, 1e-6) << k;
  }
}

// Values that fit a double but not the float they are stored in: refused, not rendered NaN.
TEST(ColladaHostile, ValuesThatFloatCannotHoldAreRefused) {
  const auto material = [](const std::string& cgl) {
    return document(R"(<library_effects><effect id="e"><extra><technique profile="CGL">)" + cgl +
                        R"(</technique></extra></effect></library_effects>
<library_materials><material id="m"><instance_effect url="#e"/></material></library_materials>)",
                    "",
                    R"(<node><instance_geometry url="#g"><bind_material><technique_common>
<instance_material symbol="m" target="#m"/></technique_common></bind_material></instance_geometry></node>)");
  };
  EXPECT_NE(error_of(material("<microfacet><alpha>1e-30</alpha><eta>1 1 1</eta><k>1 1 1</k></microfacet>"))
                .find("<alpha> 1e-30 is outside (0.0001, 10]"),
            std::string::npos);
  EXPECT_NE(
      error_of(
          material(
              "<glass><reflectance>1 1 1</reflectance><transmittance>1 1 1</transmittance><ior>1e-50</ior></glass>"))
          .find("<ior> 1e-50 is outside (0.001, 10]"),
      std::string::npos);
  EXPECT_EQ(error_of(material("<microfacet><alpha>0.001</alpha><eta>1 1 1</eta><k>1 1 1</k></microfacet>")), "");
  // A point light's colour over its attenuation: 1 / 1e-38 made every sample infinite.
  const std::string point = R"(<library_lights><light id="l"><technique_common><point><color>1 1 1</color>
<constant_attenuation>1e-38</constant_attenuation></point></technique_common></light></library_lights>)";
  EXPECT_NE(error_of(document(point, R"(<node><instance_light url="#l"/></node>)"))
                .find("emission over attenuation at unit distance, 1e+38, must be at most 1e20"),
            std::string::npos);
}

// The format ignores comments: one inside a list of numbers is skipped, not its end (a
// matrix's first row was kept and the rest read as zeros; a float_array miscounted).
TEST(ColladaHostile, ACommentInsideNumbersIsSkipped) {
  const Scene s =
      load_collada_string(document("", "",
                                   R"(<node><matrix>1 0 0 2 <!-- a row --> 0 1 0 0 0 0 1 0<![CDATA[ 0 0 0 1]]></matrix>
<instance_geometry url="#g"/></node>)"),
                          "c.dae");
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.meshes[0].positions[0].x, 1);  // -1 moved by 2
  EXPECT_EQ(s.meshes[0].positions[0].z, 0);
  EXPECT_EQ(error_of(with(document("", ""), "-1 -1 0 1 -1 0 0 1 0", "-1 -1 0 1 -1 0 <!-- x --> 0 1 0")), "");
}

// Errors say what is wrong: a triangle count against triangles (it said "3 polygons", the
// index count), a count that is no number as such (it read "x" as 0), the offset's limit.
TEST(ColladaHostile, ErrorsNameWhatIsWrong) {
  const std::string base = document("", "");
  EXPECT_NE(error_of(with(base, R"(<triangles count="1">)", R"(<triangles count="5">)"))
                .find(R"(count="5" but 1 polygons present)"),
            std::string::npos);
  EXPECT_NE(error_of(with(base, R"(<triangles count="1">)", R"(<triangles count="x">)"))
                .find(R"(count="x" is not a whole number)"),
            std::string::npos);
  EXPECT_NE(error_of(with(base, R"(source="#v" offset="0")", R"(source="#v" offset="65")"))
                .find(R"(offset="65" is over 64, the most this loader reads)"),
            std::string::npos);
  EXPECT_NE(error_of(with(base, "-1 -1 0 1 -1 0 0 1 0", "-1 -1 0 1 -1 0 0 1 0x")).find("'0x' is not a number"),
            std::string::npos);
  EXPECT_NE(
      error_of(with(base, R"(count="9">)", R"(count="99999999999999999999">)")).find("is over 18446744073709551615"),
      std::string::npos);
}

// 40,000 nodes each warned of (an unknown instance kind, a spot light) took 5.8 s to load:
// each warning counted the lines from the file's start (0.03 s now, measured by hand: time
// is for bench/, not tests). Unknown instance kinds are one warning, not one a name; lines
// are still counted right.
TEST(ColladaHostile, ManyWarnedOfNodesAreOneWarningAKind) {
  std::string nodes;
  for (int i = 0; i < 40000; ++i)
    nodes += "\n<node><instance_x" + std::to_string(i) + R"( url="#l"/><instance_light url="#l"/></node>)";
  const std::string spot = R"(<library_lights><light id="l"><technique_common><spot><color>1 1 1</color>
</spot></technique_common></light></library_lights>)";
  const std::string text = document(spot, nodes);
  const Scene s = load_collada_string(text, "many.dae");
  EXPECT_LE(s.warnings.size(), 3u);
  bool counted = false;
  for (const std::string& w : s.warnings) counted = counted || w.find("and 39999 more like it") != std::string::npos;
  EXPECT_TRUE(counted);
  const XmlText xml(text, "many.dae");
  size_t line = 1;
  for (size_t at = 0; at < text.size(); at += 997) {
    line += size_t(std::count(text.begin() + ptrdiff_t(at ? at - 997 : 0), text.begin() + ptrdiff_t(at), '\n'));
    ASSERT_EQ(xml.line_of(ptrdiff_t(at)), line) << at;
  }
  EXPECT_EQ(xml.line_of(-1), 0u);
  EXPECT_EQ(xml.line_of(ptrdiff_t(text.size()) + 5), 1 + size_t(std::count(text.begin(), text.end(), '\n')));
}

// A camera's pose beyond the traceable range only matters to --camera file: a warning
// under CS184 framing, which never uses it (it was an error at load).
TEST(ColladaHostile, AFarCameraPoseIsAWarningUnderCs184Framing) {
  const Scene s = load_collada_string(
      document(with(kCamera, "ASPECT", "1.5"),
               R"(<node><matrix>1 0 0 0 0 1 0 0 0 0 1 1e13 0 0 0 1</matrix><instance_camera url="#c"/></node>)"),
      "far-camera.dae");
  EXPECT_EQ(camera_error(s), "");
  EXPECT_NE(camera_error(s, Framing::kFile).find("eye outside +-1e12"), std::string::npos)
      << camera_error(s, Framing::kFile);
}

}  // namespace
}  // namespace tessera
