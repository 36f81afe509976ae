#include "server/metrics.h"

#include <map>
#include <set>

#include "core/util/version.h"
#include "server/histogram.h"

namespace tessera {
namespace {

class Writer {
 public:
  void head(const char* name, const char* type, const char* help) {
    out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " " + type + "\n";
  }
  template <typename V>
  void one(const char* name, const char* type, const char* help, V v) {
    head(name, type, help);
    out += std::string(name) + " " + metric_number(v) + "\n";
  }
  void counter(const char* name, const char* help, uint64_t v) { one(name, "counter", help, v); }
  void counter(const char* name, const char* help, double v) { one(name, "counter", help, v); }
  void gauge(const char* name, const char* help, uint64_t v) { one(name, "gauge", help, v); }
  void gauge(const char* name, const char* help, double v) { one(name, "gauge", help, v); }
  std::string out;
};

}  // namespace

std::string prometheus_text(const Coordinator& c) {
  const CoordinatorCounters k = c.counters();
  Writer m;
  m.head("tessera_build_info", "gauge", "The coordinator's build (git describe), always 1.");
  m.out += "tessera_build_info{version=\"" + metric_label(version()) + "\"} 1\n";
  m.counter("tessera_tasks_dispatched_total", "Tasks handed to workers.", k.tasks_dispatched);
  m.counter("tessera_results_merged_total", "Tile results merged into films.", k.results_merged);
  m.counter("tessera_results_duplicate_total",
            "Results dropped because their tile pass was already merged (or the tile was started over since they were "
            "leased).",
            k.results_duplicate);
  m.counter("tessera_results_rejected_total", "Results refused as unknown or malformed.", k.results_rejected);
  m.counter("tessera_leases_expired_total", "Leases that expired without a result.", k.leases_expired);
  m.counter("tessera_leases_released_total", "Leases given back early by workers.", k.leases_released);
  m.counter("tessera_tasks_failed_total", "Tasks a worker could not render.", k.tasks_failed);
  m.counter("tessera_samples_merged_total", "Camera samples merged.", k.samples_merged);
  m.counter("tessera_backup_leases_total",
            "Tiles leased a second time at a frame's end, to a worker that would idle (first result merged).",
            k.backup_leases);
  m.counter("tessera_result_bytes_total",
            "Compressed sums of merged results, in bytes (over tessera_samples_merged_total: the link's bytes per "
            "sample).",
            k.result_bytes);
  m.counter("tessera_splat_bytes_total",
            "Compressed splat records of merged results (--light-tracer: light paths' contributions), in bytes.",
            k.splat_bytes);
  m.counter("tessera_jobs_submitted_total", "Jobs accepted.", k.jobs_submitted);
  m.counter("tessera_jobs_refused_total", "Jobs refused at submit.", k.jobs_refused);
  m.counter("tessera_jobs_deleted_total", "Jobs deleted (tessera delete, or --keep-ended).", k.jobs_deleted);
  m.counter("tessera_jobs_requeued_total", "FAILED or CANCELLED jobs requeued.", k.jobs_requeued);
  m.counter("tessera_images_written_total", "Progressive images written.", k.images_written);
  m.counter("tessera_image_errors_total", "Progressive image writes that failed.", k.image_errors);
  m.counter("tessera_checkpoints_written_total", "Film checkpoints written (crash safety).", k.checkpoints_written);
  m.counter("tessera_checkpoint_errors_total", "Film checkpoint writes that failed.", k.checkpoint_errors);
  m.counter("tessera_jobs_restored_total", "Jobs taken up from the data folder at start.", k.jobs_restored);
  m.counter("tessera_checks_issued_total", "Merged results picked to be rendered again by another worker.",
            k.checks_issued);
  m.counter("tessera_checks_passed_total", "Checks whose second render had the same bits.", k.checks_passed);
  m.counter("tessera_check_mismatches_total", "Checks whose second render differed.", k.check_mismatches);
  m.counter("tessera_checks_skipped_total", "Checks no other worker took in time.", k.checks_skipped);
  m.counter("tessera_workers_quarantined_total", "Workers whose results differed from the coordinator's render.",
            k.workers_quarantined);
  m.counter("tessera_tiles_rendered_again_total", "Tiles started over because a quarantined worker merged into them.",
            k.tiles_rendered_again);
  const Coordinator::Queue q = c.queue();
  m.head("tessera_queue_tasks", "gauge", "Tasks of live jobs: ready to hand out, or leased to a worker.");
  m.out += "tessera_queue_tasks{state=\"ready\"} " + metric_number(uint64_t(q.tasks_ready)) +
           "\ntessera_queue_tasks{state=\"leased\"} " + metric_number(uint64_t(q.tasks_leased)) + "\n";
  m.gauge("tessera_remaining_samples", "Camera samples of live jobs not yet merged (an upper bound with -a).",
          uint64_t(q.samples_remaining));
  m.gauge("tessera_thread_samples_per_second",
          "Render speed per worker thread, measured lately (1e6 assumed before any result).",
          q.samples_per_thread_second);
  m.gauge("tessera_remaining_core_seconds",
          "Work left in core-seconds at the measured speed: the autoscaling signal (workers = this / seconds wanted).",
          q.core_seconds_remaining);
  m.counter("tessera_merge_seconds_total", "Time spent adding tile sums into films.", k.merge_seconds);
  m.head("tessera_task_seconds", "histogram", "Merged results' render time, as their workers measured it.");
  k.task_seconds.write(m.out, "tessera_task_seconds", "");
  const std::array<uint64_t, 5> counts = c.job_counts();
  m.head("tessera_jobs", "gauge", "Jobs by state.");
  const char* names[5] = {"queued", "running", "done", "cancelled", "failed"};
  for (int i = 0; i < 5; ++i)
    m.out += std::string("tessera_jobs{state=\"") + names[i] + "\"} " + metric_number(counts[size_t(i)]) + "\n";
  const std::vector<WorkerInfo> workers = c.workers();
  uint64_t busy = 0;
  for (const WorkerInfo& w : workers) busy += w.leases != 0;
  m.gauge("tessera_workers", "Live workers (heard from within the worker timeout).", uint64_t(workers.size()));
  m.gauge("tessera_workers_busy", "Workers holding a lease.", busy);
  m.gauge("tessera_uptime_seconds", "Seconds since start.", c.uptime());
  m.gauge("tessera_workers_utilization",
          "Busy over available render-thread time of all workers, last seconds (0 when idle).", c.utilization());
  // Per worker, labelled by name (stable across restarts; ids are not). Two live workers of
  // one name and host (a restart not yet forgotten) get "#2", "#3" ..., a suffix no other
  // series has (a worker may be named "a#2" itself: a series twice breaks the exposition).
  std::vector<std::string> labels;
  std::set<std::string> taken;
  for (const WorkerInfo& w : workers) {
    const std::string host = ",host=\"" + metric_label(w.host) + "\"";
    std::string label = "worker=\"" + metric_label(w.name) + "\"" + host;
    for (int n = 2; !taken.insert(label).second; ++n)
      label = "worker=\"" + metric_label(w.name + "#" + std::to_string(n)) + "\"" + host;
    labels.push_back(std::move(label));
  }
  auto per_worker = [&](const char* name, const char* type, const char* help, auto value) {
    m.head(name, type, help);
    for (size_t i = 0; i < workers.size(); ++i)
      m.out += std::string(name) + "{" + labels[i] + "} " + metric_number(value(workers[i])) + "\n";
  };
  per_worker("tessera_worker_utilization", "gauge", "Busy over available render-thread time, last seconds.",
             [](const WorkerInfo& w) { return w.utilization; });
  per_worker("tessera_worker_busy_thread_seconds_total", "counter", "Render-thread time spent rendering.",
             [](const WorkerInfo& w) { return w.busy_thread_seconds; });
  per_worker("tessera_worker_thread_seconds_total", "counter", "Render threads x wall time since registering.",
             [](const WorkerInfo& w) { return w.thread_seconds; });
  per_worker("tessera_worker_tasks_total", "counter", "Results merged from this worker since it registered.",
             [](const WorkerInfo& w) { return w.tasks_done; });
  m.out += RpcLatency::process().text();
  return m.out;
}

}  // namespace tessera
