#include "core/render/local_renderer.h"

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>

#include "core/util/thread_pool.h"

namespace tessera {

RenderResult render_image(const TileRenderer& renderer, int threads, const ProgressCallback& progress) {
  FramePlan plan(renderer.settings());
  ThreadPool pool(threads);
  std::mutex mu;  // guards plan, stats and running
  std::condition_variable cv;
  TileStats stats;
  const bool with_aovs = renderer.settings().aovs != 0;
  int running = pool.size();
  // Light paths' splats (light_tracer.h): integers added in any order, each thread's a
  // batch at a time (SplatBuffer).
  std::unique_ptr<SplatFilm> splats;
  if (renderer.light_tracing()) splats = renderer.make_splat_film();
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };

  for (int i = 0; i < pool.size(); ++i)
    pool.run([&] {
      TileStats mine;
      std::optional<SplatBuffer> splat_buffer;
      if (splats) splat_buffer.emplace(*splats);
      std::unique_lock<std::mutex> lock(mu);
      while (!plan.done()) {
        std::optional<TileTask> task = plan.take();
        if (!task) {  // every ready tile is out; the next one comes with a merge
          cv.wait(lock);
          continue;
        }
        lock.unlock();
        std::vector<AovSums> tile_aovs;
        const std::vector<PixelSums> sums = renderer.render(
            task->rect, task->sample_begin, task->sample_end, task->active.empty() ? nullptr : task->active.data(),
            &mine, nullptr, with_aovs ? &tile_aovs : nullptr, splat_buffer ? &*splat_buffer : nullptr);
        if (splat_buffer) splat_buffer->flush();
        lock.lock();
        // Our own sums always fit: anything else is a broken invariant, and stopping loudly
        // beats waiting forever for a tile that never advances.
        if (plan.merge(task->tile, task->pass, sums) != FramePlan::Merge::kMerged)
          throw std::logic_error("tessera render: the frame plan refused a tile's own sums");
        if (with_aovs) plan.add_aovs(task->tile, tile_aovs);  // integers: any order gives the same bits
        cv.notify_all();
      }
      stats.add(mine);
      --running;
      cv.notify_all();
    });

  auto report = [&](std::unique_lock<std::mutex>& lock) {
    RenderProgress p;
    p.frame_passes = plan.frame_passes_done();
    p.passes = uint32_t(plan.passes().size());
    p.fraction = plan.fraction_done();
    p.samples = plan.samples_merged();
    p.seconds = elapsed();
    lock.unlock();
    progress(p);
    lock.lock();
  };
  {
    std::unique_lock<std::mutex> lock(mu);
    while (running > 0) {
      cv.wait_for(lock, std::chrono::milliseconds(250));
      if (progress && running > 0) report(lock);
    }
    if (progress) report(lock);
  }
  pool.wait();
  RenderResult result;
  result.film = splats ? splats->fold_into(plan.film()) : plan.film();
  result.aovs = plan.aovs();
  result.stats = stats;
  result.seconds = elapsed();
  result.light_tracing = renderer.light_tracing_decision();
  if (splats) {
    result.light_paths = splats->paths();
    result.dropped_splats = splats->dropped();
  }
  return result;
}

}  // namespace tessera
