#include "worker/sender.h"

#include <spdlog/spdlog.h>

#include "core/util/thread_pool.h"
#include "wire.h"
#include "worker/clock.h"

namespace tessera::worker {

Sender::Sender(const Link& link, TaskQueue& queue, Options options) : link_(link), queue_(queue), options_(options) {
  for (int i = 0; i < kInFlight; ++i)
    threads_.emplace_back([this] {
      set_thread_name("send");
      send_loop();
    });
}

Sender::~Sender() {
  for (std::thread& t : threads_) t.join();
}

v1::ResultBatch Sender::encode(const TaskQueue::Batch& batch, double now) const {
  v1::ResultBatch results;
  const Link::Identity me = link_.identity();
  results.set_worker_id(me.id);
  results.set_worker_secret(me.secret);
  const double threads = options_.threads * (now - options_.since);
  for (const std::shared_ptr<Held>& h : batch.tasks) {
    v1::TaskResult* r = results.add_results();
    r->set_worker_id(me.id);
    r->set_task_id(h->task.task_id());
    r->set_raw_size(uint32_t(h->sums.size() * kBytesPerPixel));
    if (options_.lie) {
      std::vector<PixelSums> wrong = h->sums;
      for (PixelSums& p : wrong) p = PixelSums{p.r * 0.8, p.g * 0.8, p.b * 0.8, p.lum2 * 0.64, p.n};
      r->set_sums_zstd(encode_sums(wrong));
    } else {
      r->set_sums_zstd(encode_sums(h->sums));
    }
    if (!h->aovs.empty()) r->set_aovs_zstd(encode_aovs(h->aovs));
    if (!h->splats.empty()) {  // finished: no row adds to them any more
      for (SplatRecord& pass : h->splats) pass.normalize();
      r->set_splats_zstd(encode_splats(h->splats));
    }
    r->set_samples(h->stats.samples);
    r->set_rays(h->stats.rays.rays + h->stats.rays.shadow_rays);
    r->set_nan_samples(h->stats.nan_samples);
    r->set_render_seconds(h->last_row - h->first_row);
    r->set_busy_thread_seconds(batch.busy_thread_seconds);
    r->set_thread_seconds(threads);
  }
  return results;
}

CallPlan plan_calls(const std::vector<uint64_t>& sizes, uint64_t max_call, uint64_t max_message) {
  CallPlan plan;
  uint64_t bytes = 0;
  for (size_t i = 0; i < sizes.size(); ++i) {
    if (sizes[i] > max_message) {
      plan.too_large.push_back(i);
      continue;
    }
    if (plan.calls.empty() || (bytes + sizes[i] > max_call && !plan.calls.back().empty())) {
      plan.calls.emplace_back();
      bytes = 0;
    }
    plan.calls.back().push_back(i);
    bytes += sizes[i];
  }
  return plan;
}

void Sender::send_loop() {
  while (true) {
    const TaskQueue::Batch batch = queue_.take_finished(std::chrono::milliseconds(kLingerMs));
    if (batch.tasks.empty()) return;  // stopped, and everything finished was sent
    v1::ResultBatch all = encode(batch, now_seconds());
    // In calls of at most kMaxCallBytes (the coordinator reads a call whole, and refuses one
    // past kMaxMessageBytes: a batch of large tiles was refused, retried and dropped).
    std::vector<uint64_t> sizes;
    for (const v1::TaskResult& r : all.results()) sizes.push_back(r.ByteSizeLong());
    const uint64_t max_message = uint64_t(kMaxMessageBytes) - (1 << 20);  // (room for the call's other fields)
    const CallPlan plan = plan_calls(sizes, kMaxCallBytes, max_message);
    for (const size_t i : plan.too_large) {  // no call can carry it
      const std::string why = "its result is " + std::to_string(sizes[i]) + " bytes, past the " +
                              std::to_string(max_message) + " a call may carry (a smaller --tile fits)";
      spdlog::error("task {}: {}", all.results(int(i)).task_id(), why);
      queue_.sent(TaskQueue::Batch{{batch.tasks[i]}, 0}, false);
      link_.release(all.results(int(i)).task_id(), why);
    }
    for (const std::vector<size_t>& call : plan.calls) {
      TaskQueue::Batch part;
      part.busy_thread_seconds = batch.busy_thread_seconds;
      v1::ResultBatch results;
      results.set_worker_id(all.worker_id());
      results.set_worker_secret(all.worker_secret());
      for (const size_t i : call) {
        part.tasks.push_back(batch.tasks[i]);
        results.add_results()->Swap(all.mutable_results(int(i)));
      }
      submit(part, results);
    }
  }
}

void Sender::submit(const TaskQueue::Batch& batch, const v1::ResultBatch& results) {
  UploadBudget::Call call;  // results are in the batch's order
  for (size_t i = 0; i < batch.tasks.size(); ++i) {
    // A run's sums are one tile's whatever its passes; its splats are a record a pass.
    const uint64_t sums = results.results(int(i)).sums_zstd().size();
    const uint64_t splats = results.results(int(i)).splats_zstd().size();
    call.bytes += sums + splats;
    call.samples += double(batch.tasks[i]->stats.samples);
    call.busy += batch.tasks[i]->busy;
    call.single_pass_bytes += double(sums) * double(batch.tasks[i]->passes.size()) + double(splats);
  }
  bool sent = false;
  grpc::Status st;
  for (int attempt = 0; attempt < kAttempts && !sent; ++attempt) {
    v1::ResultAcks acks;
    call.start = now_seconds();
    st = link_.stub->SubmitResults(link_.context(30).get(), results, &acks);
    call.end = now_seconds();
    call.held = acks.held_ms() / 1000.0;
    sent = st.ok();
    if (sent) queue_.note_upload(call);
    for (int k = 0; sent && k < acks.acks_size() && k < results.results_size(); ++k)
      if (!acks.acks(k).refused().empty())  // (counted as this worker failing the task while its lease lived)
        spdlog::warn("the coordinator refused task {}'s result: {}", results.results(k).task_id(),
                     acks.acks(k).refused());
    if (!sent) {
      spdlog::debug("submit: {}", st.error_message());
      std::this_thread::sleep_for(std::chrono::milliseconds(100 << attempt));
    }
  }
  if (!sent)
    spdlog::warn(
        "the results of {} task(s) were not sent after {} attempts ({}): their leases expire and other "
        "workers render them",
        batch.tasks.size(), kAttempts, st.error_message());
  queue_.sent(batch, sent);  // unsent: their leases expire and other workers render them
}

}  // namespace tessera::worker
