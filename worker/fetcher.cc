#include "worker/fetcher.h"

#include <spdlog/spdlog.h>

#include "wire.h"
#include "worker/clock.h"

namespace tessera::worker {

Fetcher::Fetcher(const Link& link, TaskQueue& queue, const std::string& cache_dir, Backoff& backoff,
                 SceneCache::Bounds bound)
    : link_(link),
      queue_(queue),
      backoff_(backoff),
      scenes_(
          cache_dir,
          [this](const v1::FetchSceneRequest& req, const SceneCache::Piece& piece) { return fetch_scene(req, piece); },
          bound) {}

grpc::Status Fetcher::fetch_scene(const v1::FetchSceneRequest& req, const SceneCache::Piece& piece) const {
  // Each call has two minutes; a larger scene's fetch goes on in the next (SceneCache).
  const auto ctx = link_.context(120);
  const auto reader = link_.stub->FetchSceneChunks(ctx.get(), req);
  v1::SceneChunk chunk;
  try {
    while (reader->Read(&chunk)) {
      if (stop_ && *stop_) throw Stopped();
      piece(chunk);
    }
  } catch (...) {  // a piece refused: the call ends here
    ctx->TryCancel();
    while (reader->Read(&chunk)) {
    }
    reader->Finish();
    throw;
  }
  return reader->Finish();
}

Fetcher::Leased Fetcher::lease(const std::atomic<bool>& stop) {
  stop_ = &stop;
  const std::optional<LeaseRequest> size = queue_.wait_for_room(kStopPoll);
  if (!size) return {};
  v1::GetTaskRequest req;
  const Link::Identity me = link_.identity();
  req.set_worker_id(me.id);
  req.set_worker_secret(me.secret);
  req.set_max_tasks(size->max_tasks);
  if (size->max_samples > 0) req.set_max_samples(size->max_samples);
  if (size->max_passes > 1) req.set_max_passes(size->max_passes);
  v1::GetTaskResponse resp;
  const double t0 = now_seconds();
  const grpc::Status st = link_.stub->GetTask(link_.context(10).get(), req, &resp);
  if (!st.ok()) return {st, 0};
  if (resp.tasks_size() > 0) queue_.note_round_trip(now_seconds() - t0 - resp.held_ms() / 1000.0);
  backoff_.reset();
  for (const v1::Task& task : resp.tasks()) queue_.preparing(task.task_id());  // heartbeaten from now on
  for (const v1::Task& task : resp.tasks()) {
    if (stop) continue;  // stopping: the rest go back unprepared with the held ones (TaskQueue::take_held)
    enqueue(task, stop);
  }
  return {st, resp.tasks_size()};
}

void Fetcher::enqueue(const v1::Task& task, const std::atomic<bool>& stop) {
  auto h = std::make_shared<Held>();
  h->task = task;
  try {
    h->rect = from_proto(h->task.tile());
    if (!h->task.active().empty() && h->task.active().size() != size_t(h->rect.area()))
      throw WireError("active mask size");
    if (h->rect.area() <= 0) throw WireError("empty tile");
    h->prepared = scenes_.prepare(h->task);
    const RenderSettings& settings = h->prepared->renderer->settings();
    // A tile of the frame's window, no larger than its tile size (a 65536-pixel-wide one
    // would have asked for 160 GiB of sums below).
    const Rect window = settings.effective_window();
    const Rect& r = h->rect;
    if (r.x < window.x || r.y < window.y || r.x + int64_t(r.w) > window.x + int64_t(window.w) ||
        r.y + int64_t(r.h) > window.y + int64_t(window.h) || r.w > settings.tile_size || r.h > settings.tile_size)
      throw WireError("tile " + std::to_string(r.w) + "x" + std::to_string(r.h) + " at " + std::to_string(r.x) + "," +
                      std::to_string(r.y) + " is not a tile of the frame's " + std::to_string(window.w) + "x" +
                      std::to_string(window.h) + " window at tile size " + std::to_string(settings.tile_size));
    h->passes = task_passes(h->task, settings);
    h->base = task_base(h->task, h->rect, settings.sum_planes());
    if (!h->task.active().empty()) h->mask = reinterpret_cast<const uint8_t*>(h->task.active().data());
    h->sums.resize(size_t(h->rect.area()) * settings.sum_planes());
    if (settings.aovs) h->aovs.resize(size_t(h->rect.area()));
    if (h->prepared->renderer->light_tracing()) h->splats.resize(h->passes.size());
  } catch (const std::exception& e) {
    // A busy coordinator (SceneBusy) is not a failure of the task: it goes back without an
    // error, to be taken again later. Any other error: another worker may manage.
    if (dynamic_cast<const Stopped*>(&e)) return;  // given back with the held ones (TaskQueue::take_held)
    const bool busy = dynamic_cast<const SceneBusy*>(&e) != nullptr;
    spdlog::warn("task {}: {}{}", h->task.task_id(), e.what(), busy ? " (given back, to take again later)" : "");
    queue_.not_prepared(h->task.task_id());
    link_.release(h->task.task_id(), busy ? "" : e.what());
    backoff_.wait(&stop);  // either way this one backs off
    return;
  }
  const uint64_t id = h->task.task_id();
  if (!queue_.add(std::move(h))) spdlog::info("task {}: the coordinator took it back while it was prepared", id);
}

}  // namespace tessera::worker
