#include "core/render/tile_renderer.h"

#include <filesystem>
#include <stdexcept>

#include "core/light/environment.h"
#include "core/render/frame_plan.h"
#include "core/sampling/sampler.h"
#include "core/scene/animation.h"

namespace tessera {

TileRenderer::TileRenderer(const Scene& scene, const RenderSettings& settings) : rest_(&scene), settings_(settings) {
  set_up_frame(nullptr);
}

TileRenderer::TileRenderer(const TileRenderer& base, const RenderSettings& settings)
    : rest_(base.rest_), settings_(settings) {
  set_up_frame(&base);
}

void TileRenderer::set_frame(std::optional<int> frame) {
  settings_.frame = frame;
  set_up_frame(this);
}

namespace {
constexpr double kMaxEnvironmentRadiance = 1e20;  // as --env-color's and an emitter's
}  // namespace

std::shared_ptr<const EnvironmentMap> TileRenderer::load_environment(const Scene& scene,
                                                                     const RenderSettings& settings) {
  if (settings.environment_map.empty()) return nullptr;
  std::filesystem::path path(settings.environment_map);
  if (path.is_relative()) path = std::filesystem::path(scene.source).parent_path() / path;
  try {
    RgbImage image = read_environment_image(path.string());
    // Its radiance is a texel times --env-color (or 1) times --env-strength: bounded as
    // emission is (a texel of 1.6e38 dropped 45% of the samples as NaN).
    float peak = 0;
    for (const Rgb& t : image.texels) peak = std::max(peak, t.max());
    const double radiance =
        double(peak) * settings.environment_strength * settings.environment.value_or(Rgb(1.0f)).max();
    if (radiance > kMaxEnvironmentRadiance)
      throw std::runtime_error(
          path.string() + ": its brightest texel, " + std::to_string(peak) +
          (settings.environment_strength != 1 || settings.environment ? " times --env-strength and --env-color" : "") +
          ", is a radiance of " + std::to_string(radiance) + ", past 1e20");
    return std::make_shared<const EnvironmentMap>(std::move(image), settings.environment_rotation);
  } catch (const std::runtime_error& e) {
    // Named as the settings name it (a farm job's bundle path), not where it was unpacked.
    std::string why = e.what();
    if (why.rfind(path.string(), 0) == 0) why = settings.environment_map + why.substr(path.string().size());
    throw SettingsError("--env", why);
  }
}

void TileRenderer::check_settings(const Scene& scene, const RenderSettings& settings, const std::vector<int>& frames) {
  (void)load_environment(scene, settings);
  check_animation(scene, settings);
  // An animated file camera: each frame's pose (the camera node's transform alone).
  const bool animated_camera =
      scene.animation && scene.animation->camera_node >= 0 && settings.camera.framing == Framing::kFile;
  if ((!settings.camera.path && !animated_camera) || frames.empty()) {
    (void)Camera(scene, settings.at_frame().camera);  // a file camera the framing needs but cannot use
    return;
  }
  // Each frame's camera, where the path and the animation put it (only frame 0 was checked:
  // a sequence whose path crossed its target failed midway, on the farm a task at a time
  // for good; a path's target the animated camera reached, likewise).
  const Bounds objects = scene.object_bounds();
  const char* flag = !settings.camera.path                ? "--frames"
                     : settings.camera.path->keys.empty() ? "--turntable"
                                                          : "--camera-path";
  const size_t clip = animated_camera ? scene.animation->find_clip(settings.animation) : 0;
  Scene posed;  // (the camera reads its scene's camera alone, given the objects' bounds)
  RenderSettings s = settings;
  for (const int frame : frames) {
    s.frame = frame;
    try {
      if (animated_camera) {
        posed.camera = pose_camera(scene, clip, s.time());
        (void)Camera(posed, s.at_frame().camera, &objects);
      } else {
        (void)Camera(scene, s.at_frame().camera, &objects);
      }
    } catch (const SettingsError& e) {
      throw SettingsError(
          flag, "at frame " + std::to_string(frame) + ": " + std::string(e.what()).substr(e.flag().size() + 2));
    }
  }
}

bool TileRenderer::traces_light_paths(const Scene& scene, const RenderSettings& settings) {
  // (Environment lights are infinite: they carry no light paths, so the scene's own lights
  // decide, as in set_up_frame. A pose moves lights and surfaces, never what they are.)
  const RenderSettings s = settings.at_frame();
  return tessera::light_tracing_decision(scene, LightSet(scene), Camera(scene, s.camera), s).on;
}

void TileRenderer::check_animation(const Scene& scene, const RenderSettings& settings) {
  if (settings.animation.empty()) return;
  if (!scene.animation) throw SettingsError("--animation", "the scene has no animations");
  try {
    (void)scene.animation->find_clip(settings.animation);
  } catch (const std::invalid_argument& e) {
    throw SettingsError("--animation", e.what());
  }
}

void TileRenderer::set_up_frame(const TileRenderer* share) {
  if (!settings_.splat_exponent)  // (tessera render's; a farm job's comes set with its tasks)
    settings_.splat_exponent =
        splat_exponent_for(rest_->lights, int64_t(settings_.camera.width) * settings_.camera.height);
  const RenderSettings s = settings_.at_frame();
  check_animation(*rest_, settings_);
  if (rest_->animation && settings_.frame) {
    const size_t clip = rest_->animation->find_clip(settings_.animation);
    posed_ = std::make_shared<const Scene>(pose_scene(*rest_, clip, settings_.time()));
    scene_ = posed_.get();
  } else {
    posed_.reset();
    scene_ = rest_;
  }
  // What the settings add to the scene's lights: an environment (--env, --env-color), or
  // the neutral default one for a scene with no light at all. Its image is loaded once and
  // shared by every renderer that shares these lights.
  const bool same_environment = share && share->settings_.environment == settings_.environment &&
                                share->settings_.default_environment == settings_.default_environment &&
                                share->settings_.environment_map == settings_.environment_map &&
                                share->settings_.environment_strength == settings_.environment_strength &&
                                share->settings_.environment_rotation == settings_.environment_rotation;
  std::vector<Light> extra;
  if (settings_.environment || !settings_.environment_map.empty() || (scene_->unlit && settings_.default_environment)) {
    Light env;
    env.kind = Light::Kind::kEnvironment;
    env.name = !settings_.environment_map.empty() ? settings_.environment_map
               : settings_.environment            ? "environment"
                                                  : "default environment";
    const Rgb base = settings_.environment.value_or(Rgb(RenderSettings::kDefaultEnvironment));
    env.color = base * settings_.environment_strength;
    if (!settings_.environment_map.empty())
      env.map = same_environment && share->environment_ ? share->environment_ : load_environment(*rest_, settings_);
    environment_ = env.map;
    extra.push_back(env);
  }
  if (posed_) {
    // Only what moves is built per pose; the rest is one BVH for every frame, instanced.
    if (share && share->static_part_) static_part_ = share->static_part_;
    if (!static_part_) {
      auto part = std::make_shared<StaticPart>();
      part->moving.assign(rest_->meshes.size(), false);
      for (const SceneAnimation::MeshBinding& b : rest_->animation->meshes) part->moving[b.mesh] = true;
      part->accel = std::make_shared<const Accel>(*rest_, part->moving);
      part->rest_bounds = rest_->object_bounds();
      static_part_ = part;
    }
    accel_ = std::make_shared<const Accel>(*scene_, static_part_->accel, static_part_->moving);
    lights_ = std::make_shared<const LightSet>(*scene_, extra);
  } else {
    // A static scene's BVH serves every frame and every setting; its lights too, unless
    // the settings add other ones.
    const bool shared = share && share->accel_scene_ == rest_;
    if (shared)
      accel_ = share->accel_;
    else if (accel_scene_ != scene_ || !accel_)
      accel_ = std::make_shared<const Accel>(*scene_);
    if (shared && same_environment)
      lights_ = share->lights_;
    else
      lights_ = std::make_shared<const LightSet>(*scene_, extra);
  }
  accel_scene_ = scene_;
  camera_.emplace(*scene_, s.camera, posed_ ? &static_part_->rest_bounds : nullptr);
  integrator_.emplace(*scene_, *accel_, *lights_, s);
  light_tracer_.reset();
  light_decision_ = tessera::light_tracing_decision(*scene_, *lights_, *camera_, s);
  if (light_decision_.on) {
    light_tracer_.emplace(*scene_, *accel_, *lights_, *camera_, s);
    integrator_->leave_to_light_tracer(light_tracer_->traced_lights(), LightTracer::kMaxSmoothVertices,
                                       light_tracer_->target_materials());
    integrator_->set_specular_splits(LightTracer::kSpecularSplits);
  }
}

std::unique_ptr<SplatFilm> TileRenderer::make_splat_film() const {
  return std::make_unique<SplatFilm>(settings_.effective_window(),
                                     int64_t(settings_.camera.width) * settings_.camera.height, settings_.halves(),
                                     settings_.splat_exponent.value_or(0));
}

std::vector<PixelSums> TileRenderer::render(const Rect& rect, uint32_t s0, uint32_t s1, const uint8_t* active,
                                            TileStats* stats, const std::atomic<bool>* cancel,
                                            std::vector<AovSums>* aovs, SplatSink* splats) const {
  if (light_tracer_ && !splats) throw std::logic_error("TileRenderer::render: light tracing without a splat sink");
  const size_t area = size_t(rect.area());
  const bool halves = settings_.halves();
  std::vector<PixelSums> out(area * settings_.sum_planes());
  if (aovs) aovs->assign(area, AovSums{});
  const int width = settings_.camera.width, height = settings_.camera.height;
  const bool lens = camera_->is_thin_lens();
  TileStats local;
  // Checked per pixel, not per row: a row of a many-sample pass can take seconds.
  auto cancelled = [cancel] { return cancel && cancel->load(std::memory_order_relaxed); };
  const uint64_t seed = settings_.sample_seed();
  for (int y = 0; y < rect.h && !cancelled(); ++y) {
    for (int x = 0; x < rect.w; ++x) {
      if (cancelled()) break;
      const size_t k = size_t(y) * rect.w + x;
      if (active && !active[k]) continue;
      const int px = rect.x + x, py = rect.y + y;  // image coordinates, row 0 at the top
      const uint64_t pixel_id = uint64_t(py) * uint64_t(width) + uint64_t(px);
      PixelSums sums, odd;  // odd: the odd-numbered samples' (half-buffers only)
      FirstHit first;       // (filled, and reset for each sample, only when AOVs are asked for)
      for (uint32_t s = s0; s < s1; ++s) {
        Sampler sampler(seed, pixel_id, s);
        const Vec2 jitter = sampler.next_2d();
        const Vec2 u_lens = lens ? sampler.next_2d() : Vec2{};
        // The camera counts rows from the bottom (CS184 convention).
        const Ray ray = camera_->generate(float(px) + jitter.x, float(height - 1 - py) + jitter.y, u_lens);
        if (aovs) first = FirstHit{};
        const Rgb L = integrator_->radiance(ray, sampler, local.rays, aovs ? &first : nullptr);
        ++local.samples;
        if (light_tracer_ && LightTracer::traces(pixel_id, s))
          light_tracer_->trace(seed, pixel_id, s, *splats, halves && (s & 1), local.rays);
        // Beyond kMaxSampleValue is as useless as NaN (only a delta light nearer than 1e-5
        // gets there), and dropping it keeps our own sums always plausible (frame_plan.h).
        if (!L.is_finite() || L.max() > kMaxSampleValue) {
          ++local.nan_samples;
          continue;
        }
        if (aovs) (*aovs)[k].add_sample(first, s);
        const double lum = L.luminance();
        sums.r += L.r;
        sums.g += L.g;
        sums.b += L.b;
        sums.lum2 += lum * lum;
        ++sums.n;
        if (halves && (s & 1)) {
          odd.r += L.r;
          odd.g += L.g;
          odd.b += L.b;
          odd.lum2 += lum * lum;
          ++odd.n;
        }
      }
      out[k] = sums;
      if (halves) out[area + k] = odd;
    }
  }
  if (stats) stats->add(local);
  return out;
}

std::vector<PixelSums> TileRenderer::render_passes(const Rect& rect,
                                                   const std::vector<std::pair<uint32_t, uint32_t>>& passes,
                                                   const PixelSums* base, const uint8_t* active, TileStats* stats,
                                                   const std::atomic<bool>* cancel, std::vector<AovSums>* aovs,
                                                   std::vector<SplatRecord>* splats) const {
  if (light_tracer_ && !splats) throw std::logic_error("TileRenderer::render_passes: light tracing without splats");
  if (splats) splats->clear();
  std::optional<SplatList> list;
  if (light_tracer_) list.emplace(settings_.effective_window(), settings_.halves());
  if (passes.size() == 1 && !base) {
    std::vector<PixelSums> sums =
        render(rect, passes[0].first, passes[0].second, active, stats, cancel, aovs, list ? &*list : nullptr);
    if (list) splats->push_back(list->take());
    return sums;
  }
  std::vector<PixelSums> sums(size_t(rect.area()) * settings_.sum_planes());
  if (base) std::copy_n(base, sums.size(), sums.begin());
  if (aovs) aovs->assign(size_t(rect.area()), AovSums{});
  std::vector<AovSums> pass_aovs;
  for (const auto& [s0, s1] : passes) {
    const std::vector<PixelSums> pass =
        render(rect, s0, s1, active, stats, cancel, aovs ? &pass_aovs : nullptr, list ? &*list : nullptr);
    if (list) splats->push_back(list->take());
    for (size_t i = 0; i < sums.size(); ++i) sums[i].add(pass[i]);  // Film::add_tile's order
    if (aovs)
      for (size_t i = 0; i < aovs->size(); ++i) (*aovs)[i].add(pass_aovs[i]);
  }
  return sums;
}

}  // namespace tessera
