// Camera framing (CS184 section 2.2/2.3) and the thin lens.
#include "core/camera/camera.h"

#include <gtest/gtest.h>

#include "core/render/settings.h"
#include "core/scene/collada/collada_loader.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

TEST(Camera, Cs184FramingOfTheCornellBoxes) {
  TESSERA_REQUIRE_SHARED_SCENE(path, "CBspheres.dae");
  const Scene scene = load_collada_file(path);
  CameraSettings cs;
  cs.width = 480;
  cs.height = 360;
  const Camera cam(scene, cs);
  // Format doc 2.2: eye (0, 0.75, 4.8023) looking -Z; 2.3: 30.68 x 23.25 degrees at 480x360.
  EXPECT_NEAR(cam.eye().x, 0, 1e-3);
  EXPECT_NEAR(cam.eye().y, 0.75, 1e-3);
  EXPECT_NEAR(cam.eye().z, 4.8023, 2e-3);
  EXPECT_NEAR(cam.forward().z, -1, 1e-5);
  EXPECT_NEAR(2 * std::atan(cam.tan_half_hfov()) * 180 / M_PI, 30.68, 0.01);
  EXPECT_NEAR(2 * std::atan(cam.tan_half_vfov()) * 180 / M_PI, 23.25, 0.01);
  cs.width = 800;
  cs.height = 600;
  EXPECT_NEAR(2 * std::atan(Camera(scene, cs).tan_half_hfov()) * 180 / M_PI, 49.13, 0.01);
}

TEST(Camera, ThinLensRaysThroughOnePixelMeetOnTheFocalPlane) {
  Scene scene;
  scene.camera.present = true;
  CameraSettings cs;
  cs.framing = Framing::kFile;
  cs.lens_radius = 0.2f;
  cs.focal_distance = 3.0f;
  const Camera cam(scene, cs);
  Vec3 first;
  for (int i = 0; i < 16; ++i) {
    const Ray r = cam.generate(100.5f, 200.5f, Vec2{(i % 4 + 0.5f) / 4, (i / 4 + 0.5f) / 4});
    const float t = -3.0f / r.d.z;  // the camera looks down -z from the origin
    const Vec3 p = r.o + r.d * t;
    if (i == 0) first = p;
    EXPECT_NEAR(p.x, first.x, 1e-5f);
    EXPECT_NEAR(p.y, first.y, 1e-5f);
    EXPECT_LE(length(r.o), 0.2f + 1e-6f);
  }
}

TEST(Camera, PinholeIsTheZeroApertureLimit) {
  Scene scene;
  scene.camera.present = true;
  CameraSettings cs;
  cs.framing = Framing::kFile;
  const Ray a = Camera(scene, cs).generate(10, 20, {0.9f, 0.1f});
  EXPECT_EQ(a.o.x, 0);
  EXPECT_EQ(a.o.y, 0);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// A file's orthographic camera (glTF): rays along the view from a rectangle ymag high
// and as wide as the image's aspect, starting at znear.
TEST(Camera, AnOrthographicCameraSendsParallelRaysFromItsViewRectangle) {
  Scene s;
  s.camera.present = true;
  s.camera.eye = {1, 2, 10};
  s.camera.ortho_half_height = 3;
  s.camera.znear = 0.5f;
  s.camera.zfar = 100;
  CameraSettings c;
  c.framing = Framing::kFile;
  c.width = 200;
  c.height = 100;
  c.lens_radius = 0.5f;  // ignored: parallel rays have no depth of field
  const Camera cam(s, c);
  const Ray corner = cam.generate(0, 0, {0.3f, 0.7f}), centre = cam.generate(100, 50, {0.3f, 0.7f});
  EXPECT_FLOAT_EQ(corner.o.x, 1 - 6);  // half width: 3 x 200/100
  EXPECT_FLOAT_EQ(corner.o.y, 2 - 3);
  EXPECT_FLOAT_EQ(corner.o.z, 10);
  EXPECT_FLOAT_EQ(centre.o.x, 1);
  EXPECT_FLOAT_EQ(centre.o.y, 2);
  for (const Ray& r : {corner, centre}) {
    EXPECT_FLOAT_EQ(r.d.z, -1);
    EXPECT_FLOAT_EQ(r.tmin, 0.5f);
    EXPECT_FLOAT_EQ(r.tmax, 100);
  }
}

// A .dae whose camera pose is unusable loads (collada_test.cc); CS184 framing renders it,
// and asking for the file's camera is refused naming the problem.
TEST(Camera, AnUnusableFilePoseServesCs184FramingAndIsRefusedForFileFraming) {
  Scene s;
  s.camera.present = true;
  s.camera.cs184_dir = {0, 0, 1};
  s.camera.pose_problem = "<library_cameras>/<camera id=\"cam\">: need 0 <= znear < zfar";
  s.spheres.push_back(Sphere{"ball", {0, 0, 0}, 1, 0, -1});
  CameraSettings c;
  c.framing = Framing::kCs184;
  EXPECT_NO_THROW(Camera(s, c));
  c.framing = Framing::kFile;
  try {
    Camera camera(s, c);
    ADD_FAILURE() << "the unusable pose was used";
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--camera");
    EXPECT_NE(std::string(e.what()).find("need 0 <= znear < zfar"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: the camera checked its eye but not its lens, whose rays start up to the
// radius off the eye (2e18: Embree aborted the process) and aim through the focal plane.
TEST(Camera, ALensOrFocalDistanceRaysCannotCarryIsRefused) {
  Scene scene;
  scene.camera.present = true;
  CameraSettings cs;
  cs.framing = Framing::kFile;
  cs.lens_radius = 2e18f;
  try {
    Camera(scene, cs);
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_NE(std::string(e.what()).find("lens radius 2e+18"), std::string::npos) << e.what();
  }
  cs.lens_radius = 0.1f;
  cs.focal_distance = 1e20f;
  EXPECT_THROW(Camera(scene, cs), SettingsError);
  cs.focal_distance = 1e12f;
  EXPECT_NO_THROW(Camera(scene, cs));
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a perspective file camera clipped at znear and zfar along each ray, not
// at planes, so a wall at depth 4.5 with zfar 5 showed at the image's centre and vanished
// at its corners (90 degree view: the corner rays reach depth 5 at 5 / cos). glTF's
// projection matrices (and Blender's clip_start and clip_end, which it maps them to) clip at
// planes: a ray's limits are the depths over its cosine to the axis, pinhole and thin lens,
// and Camera::connect clips the light tracer's connections the same way.
TEST(Camera, AFileCamerasClipDistancesArePlanes) {
  Scene s;
  s.camera.present = true;
  s.camera.eye = {0, 0, 0};
  s.camera.forward = {0, 0, -1};
  s.camera.up = {0, 1, 0};
  s.camera.xfov_deg = 90;
  s.camera.aspect_ratio = 1;
  s.camera.znear = 0.5f;
  s.camera.zfar = 5;
  CameraSettings c;
  c.framing = Framing::kFile;
  c.width = c.height = 100;
  for (const float lens : {0.0f, 0.1f}) {
    c.lens_radius = lens;
    c.focal_distance = 3;
    const Camera cam(s, c);
    for (const auto& [fx, fy] : {std::pair{50.0f, 50.0f}, {0.5f, 0.5f}, {99.5f, 50.0f}}) {
      const Ray r = cam.generate(fx, fy, {0.3f, 0.7f});
      const float cos_axis = -r.d.z;
      EXPECT_NEAR(r.tmin * cos_axis, 0.5f, 1e-5f) << fx << " " << fy << " lens " << lens;
      EXPECT_NEAR(r.tmax * cos_axis, 5.0f, 1e-4f) << fx << " " << fy << " lens " << lens;
    }
    // A point at depth 4.5 near a corner is seen; one at depth 5.5 straight ahead is not.
    CameraConnection cc;
    EXPECT_TRUE(cam.connect(Vec3{-4.2f, -4.2f, -4.5f}, {0.3f, 0.7f}, &cc)) << lens;
    EXPECT_NEAR(cc.near * (4.5f / cc.dist), 0.5f, 1e-4f);  // the near plane along the connection
    EXPECT_FALSE(cam.connect(Vec3{0, 0, -5.5f}, {0.3f, 0.7f}, &cc)) << lens;
  }
}

}  // namespace
}  // namespace tessera
