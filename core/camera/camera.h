// Pinhole and thin-lens cameras with CS184 framing (format doc 2.2-2.5); a file's
// orthographic camera (glTF) with the file's framing: parallel rays, no depth of field.
//
// Parameters:
//   width, height   output size in pixels; with CS184 framing the field of view follows it
//                   (the image is the centred window of an 800x600 view, doc 2.3)
//   lens_radius     thin-lens radius in scene units (-b); 0 gives a pinhole (default)
//   focal_distance  distance of the plane in focus along the optical axis (-d), default 4.7
//   framing         kCs184: eye on the bounding box's diagonal, +Y up (default for .dae);
//                   kFile: the file's own camera pose and field of view
//   pose            a camera path's values for this frame, in place of the framing's:
//                   eye, target (else the framing's direction), up, vertical fov; then the
//                   turntable's turn about its axis
#pragma once

#include <memory>

#include "core/camera/camera_path.h"
#include "core/math/ray.h"
#include "core/math/vec.h"
#include "core/scene/scene.h"

namespace tessera {

enum class Framing { kCs184, kFile };

struct CameraSettings {
  int width = 480, height = 360;
  float lens_radius = 0;
  float focal_distance = 4.7f;
  Framing framing = Framing::kCs184;
  // --camera-path / --turntable: the sequence's path (null: none), and what the frame being
  // rendered takes from it (RenderSettings::at_frame fills it in; the camera applies it).
  std::shared_ptr<const CameraPath> path;
  CameraPath::At pose;
};

class Camera {
 public:
  Camera(const Scene& scene, const CameraSettings& settings);

  // A ray through film position (fx, fy) in pixels, y counted from the bottom row;
  // u_lens is used only by the thin lens.
  Ray generate(float fx, float fy, Vec2 u_lens) const;
  bool is_thin_lens() const { return lens_radius_ > 0; }
  Vec3 eye() const { return eye_; }
  Vec3 forward() const { return -z_; }
  float tan_half_hfov() const { return tan_h_; }
  float tan_half_vfov() const { return tan_v_; }

 private:
  Vec3 eye_, x_, y_, z_;  // camera-to-world basis; the camera looks along -z_
  float tan_h_ = 0, tan_v_ = 0;
  float ortho_w_ = 0, ortho_h_ = 0;  // an orthographic camera's half width and height (0: perspective)
  float inv_w_ = 0, inv_h_ = 0;
  float lens_radius_ = 0, focal_distance_ = 1;
  float tmin_ = 0, tmax_ = 1e30f;
};

}  // namespace tessera
