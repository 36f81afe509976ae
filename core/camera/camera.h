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

// A point seen by the camera, for light tracing (Camera::connect): where on the film it
// lands and the importance that carries it there.
struct CameraConnection {
  float fx = 0, fy = 0;  // film position in pixels, y counted from the bottom row (as generate())
  Vec3 lens;             // the point on the lens (the eye for a pinhole)
  Vec3 wi;               // unit, from the seen point toward `lens`
  float dist = 0;        // from the seen point to `lens`
  // Along the connection, from `lens` to the near clip plane (0 without one): camera rays
  // start there, so what lies nearer is not seen and blocks nothing.
  float near = 0;
  // We / pdf: the importance of the ray (lens -> point) over the density of choosing the
  // lens point, per unit area at the point, without the point's own cosine:
  // 1 / (A cos^3 theta dist^2), A the film's area at unit distance, theta the ray's angle
  // to the optical axis. A light path's value at a pixel is beta f |cos| x this, and a
  // pixel's estimate from N light paths is (width x height / N) x the sum of those values.
  float weight = 0;
};

class Camera {
 public:
  // `objects`: scene.object_bounds(), where the caller has it (a check of every frame of a
  // sequence walks the vertices once, not once a frame).
  Camera(const Scene& scene, const CameraSettings& settings, const Bounds* objects = nullptr);

  // A ray through film position (fx, fy) in pixels, y counted from the bottom row;
  // u_lens is used only by the thin lens.
  Ray generate(float fx, float fy, Vec2 u_lens) const;
  // The film position and importance of point p seen through the lens point u_lens (thin
  // lens; unused by a pinhole). False where the camera cannot see p: behind it, outside the
  // film, nearer or farther than the clip planes, or an orthographic camera (light tracing
  // needs a perspective one).
  bool connect(Vec3 p, Vec2 u_lens, CameraConnection* out) const;
  bool is_orthographic() const { return ortho_h_ > 0; }
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
  // A file camera's clip planes, as depths along the optical axis (glTF's znear and zfar:
  // planes, as the spec's projection matrices and Blender's clip_start and clip_end have
  // them); a ray's limits are these over its cosine to the axis. None: 0 and 1e30.
  float tmin_ = 0, tmax_ = 1e30f;
  bool clips_ = false;
};

}  // namespace tessera
