#include "core/render/local_renderer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>

namespace tessera {

bool pixel_converged(const PixelSums& p, float tolerance) {
  if (p.n < 2) return false;
  const double mu = p.lum_sum() / p.n;
  const double half_width = 1.96 * std::sqrt(p.sample_variance() / p.n);
  return half_width <= tolerance * mu;
}

RenderResult render_image(const TileRenderer& renderer, int threads, int tile_size, const ProgressCallback& progress) {
  const RenderSettings& s = renderer.settings();
  const Rect window = s.effective_window();
  if (threads <= 0) threads = int(std::max(1u, std::thread::hardware_concurrency()));
  tile_size = std::max(1, tile_size);

  std::vector<Rect> tiles;
  for (int y = window.y; y < window.y + window.h; y += tile_size)
    for (int x = window.x; x < window.x + window.w; x += tile_size)
      tiles.push_back(
          {x, y, std::min(tile_size, window.x + window.w - x), std::min(tile_size, window.y + window.h - y)});

  RenderResult result{Film(window), {}, 0};
  std::vector<uint8_t> active(size_t(window.area()), 1);
  const auto passes = s.passes();
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(); };
  const double total_work = double(window.area()) * std::max(1, s.spp);
  double done_work = 0;

  for (size_t pass = 0; pass < passes.size(); ++pass) {
    const auto [s0, s1] = passes[pass];
    std::atomic<size_t> next{0};
    std::mutex mu;
    std::condition_variable cv;
    size_t finished = 0;
    TileStats pass_stats;
    auto worker = [&] {
      std::vector<uint8_t> mask;
      TileStats stats;
      for (size_t t; (t = next.fetch_add(1)) < tiles.size();) {
        const Rect& r = tiles[t];
        mask.resize(size_t(r.area()));
        for (int y = 0; y < r.h; ++y)
          for (int x = 0; x < r.w; ++x)
            mask[size_t(y) * r.w + x] = active[size_t(r.y - window.y + y) * window.w + (r.x - window.x + x)];
        const std::vector<PixelSums> sums = renderer.render(r, s0, s1, mask.data(), &stats);
        result.film.add_tile(r, sums);  // tiles of one pass never overlap: no race
        std::lock_guard<std::mutex> lock(mu);
        ++finished;
        cv.notify_one();
      }
      std::lock_guard<std::mutex> lock(mu);
      pass_stats.add(stats);
    };
    std::vector<std::thread> pool;
    for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
    {
      std::unique_lock<std::mutex> lock(mu);
      while (finished < tiles.size()) {
        cv.wait_for(lock, std::chrono::milliseconds(250));
        if (progress) {
          RenderProgress p;
          p.pass = int(pass);
          p.passes = int(passes.size());
          p.fraction = (done_work + double(s1 - s0) * window.area() * double(finished) / tiles.size()) / total_work;
          p.samples = result.stats.samples;
          p.seconds = elapsed();
          lock.unlock();
          progress(p);
          lock.lock();
        }
      }
    }
    for (std::thread& t : pool) t.join();
    result.stats.add(pass_stats);
    done_work += double(s1 - s0) * window.area();
    if (s.adaptive)
      for (size_t i = 0; i < active.size(); ++i)
        if (active[i] && pixel_converged(result.film.pixels()[i], s.adaptive_tolerance)) active[i] = 0;
  }
  result.seconds = elapsed();
  if (progress) {
    RenderProgress p;
    p.pass = p.passes = int(passes.size());
    p.fraction = 1;
    p.samples = result.stats.samples;
    p.seconds = result.seconds;
    progress(p);
  }
  return result;
}

}  // namespace tessera
