#include "server/submission.h"

#include "core/render/splats.h"
#include "core/render/tile_renderer.h"
#include "core/scene/scene_error.h"
#include "core/util/log.h"
#include "core/util/text.h"
#include "server/request_error.h"
#include "server/sequence_scheduler.h"

namespace tessera {

Submission prepare_submission(const v1::SubmitJobRequest& req, const Admission& a, JobMeta meta, SceneStore& scenes,
                              JobStore& store, const std::string& data_dir, SceneUploads* uploads) {
  const auto refuse = [](const char* what) { return RequestError(RequestError::Code::kInvalidArgument, what); };
  std::string main_file = req.main_file();
  RenderSettings settings = a.settings;
  try {
    // A bad scene is refused here, and settings that ask it for what it has not. Whether
    // its frames trace light paths is decided here too (auto: on or off), so that every
    // result of a frame must carry splats or none (ResultIntake::result_splats). A scene
    // whose bytes are kept already is loaded from the coordinator's copy for this check.
    const auto check = [&](const Scene& scene) {
      TileRenderer::check_settings(scene, a.settings, a.frames);
      if (a.settings.light_tracer != RenderSettings::LightTracer::kOff)
        settings.light_tracer = TileRenderer::traces_light_paths(scene, a.settings) ? RenderSettings::LightTracer::kOn
                                                                                    : RenderSettings::LightTracer::kOff;
      // As tessera render computes it from the scene: every task and the image's fold use this one.
      settings.splat_exponent =
          splat_exponent_for(scene.lights, int64_t(a.settings.camera.width) * a.settings.camera.height);
    };
    if (req.upload_id().empty())
      meta.scene_hash = scenes.add(req.main_file(), req.files(), check);
    else if (uploads)
      meta.scene_hash = uploads->submit(req.upload_id(), meta.owner, check, &main_file);
    else
      throw RequestError(RequestError::Code::kFailedPrecondition, "this coordinator takes no scene uploads");
  } catch (const WireError& e) {
    throw refuse(e.what());
  } catch (const SettingsError& e) {
    throw refuse(e.what());
  } catch (const SceneError& e) {
    throw refuse(e.what());
  }
  // Shown to every user; its length was bounded at admission (a name) or by the upload (a file).
  const std::string& name = req.name().empty() ? main_file : req.name();
  meta.name = peer_text(name, name.size());
  meta.main_file = main_file;
  meta.priority = req.priority();
  meta.scene_bytes = a.scene_bytes;
  meta.submitted_at = store.wall();
  // A still's tasks carry only what its frame takes from a camera path, as a sequence's
  // frames do (SequenceScheduler::make_frame); the sequence keeps the whole path.
  if (a.frames.empty()) settings.keep_frames_camera_only();
  meta.settings = to_proto(settings);
  Submission sub;
  if (a.frames.empty()) {
    sub.job = std::make_shared<Job>(meta, settings);
  } else {
    sub.sequence = std::make_shared<Sequence>(meta, settings, a.frames);
    sub.sequence->prepared = SequenceScheduler::make_frame(*sub.sequence, 0);
  }
  StoredJob row;
  row.meta = std::move(meta);
  row.frames = a.frames;
  try {
    store.add(row);
  } catch (const std::exception& e) {
    spdlog::error("submit: {}", e.what());
    scenes.release(row.meta.scene_hash);
    try {  // off the disk too, unless a job the database knows names it (asked; if it cannot say, the next start prunes
           // it)
      if (store.scene_users(row.meta.scene_hash) == 0) scenes.remove_if_unused(row.meta.scene_hash);
    } catch (const std::exception&) {
    }
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "the coordinator cannot record the job: " + without_dir(e.what(), data_dir));
  }
  return sub;
}

}  // namespace tessera
