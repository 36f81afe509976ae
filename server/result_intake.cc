#include "server/result_intake.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <utility>

#include "core/render/light_tracer.h"

namespace tessera {

std::vector<PixelSums> result_sums(const v1::TaskResult& result, size_t pixels) {
  if (result.raw_size() != pixels * kBytesPerPixel) throw WireError("raw size does not match the tile");
  return decode_sums(result.sums_zstd(), pixels);
}

namespace {
// Whether a result shows any light: a sum besides the sample counts, or a splat.
bool shows_light(const std::vector<PixelSums>& sums, const std::vector<SplatRecord>& splats) {
  for (const SplatRecord& r : splats)
    if (!r.entries.empty()) return true;
  for (const PixelSums& p : sums)
    if (p.r != 0 || p.g != 0 || p.b != 0 || p.lum2 != 0) return true;
  return false;
}
}  // namespace

bool ResultIntake::still_wanted(const Lease& l, const Job& job) {
  // Not wanted: merged already, or leased before its tile was taken back (a liar's work
  // undone), when it may build on what was taken back (a run's base, an adaptive pass's mask).
  return job.plan.wants(l.tile, l.pass) && l.tile_resets == job.tile_resets[l.tile];
}

std::optional<Lease> ResultIntake::wanted(const v1::TaskResult& result, v1::ResultAck& ack) {
  const Lease* l = p_.leases.known(result.task_id());
  if (!l && !p_.verifier.quarantined(result.worker_id()) &&
      p_.leases.was_merged(result.task_id())) {  // its passes merged (only the id is kept)
    ++p_.counters.results_duplicate;
    ack.set_duplicate(true);
    return std::nullopt;
  }
  // Never issued, or issued to another worker: only the lease's holder may answer it.
  if (!l || l->worker != result.worker_id() || p_.verifier.quarantined(l->worker)) {
    ++p_.counters.results_rejected;
    return std::nullopt;
  }
  if (l->check) return *l;  // the Verifier's
  const Job* job = p_.jobs.find_job(l->job);
  if (!job || !job->live()) return std::nullopt;
  if (!still_wanted(*l, *job)) {
    ++p_.counters.results_duplicate;
    ack.set_duplicate(true);
    return std::nullopt;
  }
  return *l;
}

SplatLimits ResultIntake::splat_limits(const RenderSettings& s, const Rect& tile,
                                       const std::vector<std::pair<uint32_t, uint32_t>>& passes) {
  SplatLimits l;
  l.records = passes.size();
  l.area = uint64_t(s.effective_window().area());
  l.planes = s.sum_planes();
  uint64_t most = 0;  // a record is a pass's: the most light paths a pixel traces in one
  for (const auto& [s0, s1] : passes) most = std::max(most, LightTracer::max_paths_per_pixel(s0, s1));
  l.max_paths = uint64_t(tile.area()) * most;
  l.max_splats_per_path = uint64_t(std::max(1, s.max_depth));
  return l;
}

std::vector<SplatRecord> ResultIntake::result_splats(const v1::TaskResult& result, RenderSettings::LightTracer mode,
                                                     const SplatLimits& limits) {
  using LT = RenderSettings::LightTracer;
  if (result.splats_zstd().empty()) {
    if (mode == LT::kOn) throw WireError("splats: none from a frame that traces light paths");
    return {};
  }
  if (mode == LT::kOff) throw WireError("splats: from a frame that traces no light paths");
  return decode_splats(result.splats_zstd(), limits);
}

ResultIntake::Batch ResultIntake::screen(const std::vector<const v1::TaskResult*>& results) {
  Batch b;
  b.results = results;
  b.acks.resize(results.size());
  std::set<std::pair<uint64_t, uint64_t>> seen;  // a task's result twice in one batch: the first only
  for (size_t i = 0; i < results.size(); ++i) {
    if (!seen.emplace(results[i]->task_id(), results[i]->worker_id()).second) {
      ++p_.counters.results_duplicate;
      b.acks[i].set_duplicate(true);
      continue;
    }
    std::optional<Lease> lease = wanted(*results[i], b.acks[i]);
    if (!lease) continue;
    if (lease->check) {
      b.checks.emplace_back(i, std::move(*lease));
      continue;
    }
    const FramePlan& plan = p_.jobs.job(lease->job).plan;
    b.incoming.push_back({i,
                          size_t(plan.tiles()[lease->tile].area()),
                          plan.settings().sum_planes(),
                          plan.run_samples(lease->pass, lease->pass_count),
                          plan.settings().aovs != 0,
                          std::nullopt,
                          {},
                          splat_limits(plan.settings(), plan.tiles()[lease->tile],
                                       pass_run(plan.settings(), lease->pass, lease->pass_count)),
                          plan.settings().light_tracer,
                          {},
                          false,
                          {}});
  }
  return b;
}

uint64_t ResultIntake::decoded_bytes(const Batch& b, const Incoming& in) {
  const v1::TaskResult& r = *b.results[in.index];
  uint64_t bytes = uint64_t(in.pixels) * in.planes * sizeof(PixelSums);
  if (in.aovs_wanted) bytes += uint64_t(in.pixels) * sizeof(AovSums);
  // Splats as declared (decode_splats refuses more than the task allows before allocating).
  if (!r.splats_zstd().empty()) bytes += splats_declared_bytes(r.splats_zstd());
  return bytes;
}

size_t ResultIntake::slice_end(const Batch& b, size_t first) {
  size_t last = first;
  uint64_t bytes = 0;
  while (last < b.incoming.size()) {
    const uint64_t more = decoded_bytes(b, b.incoming[last]);
    if (last > first && bytes + more > kDecodedBytesPerSlice) break;
    bytes += more;
    ++last;
  }
  return last;
}

void ResultIntake::free_decoded(Batch& b, size_t first, size_t last) {
  for (size_t k = first; k < last; ++k) {
    Incoming& in = b.incoming[k];
    in.sums.reset();
    std::vector<AovSums>().swap(in.aovs);
    std::vector<SplatRecord>().swap(in.splats);
  }
}

void ResultIntake::decode(Batch& b, size_t first, size_t last) {
  for (size_t k = first; k < last; ++k) try {
      Incoming& in = b.incoming[k];
      const v1::TaskResult& r = *b.results[in.index];
      if (in.aovs_wanted)
        in.aovs = decode_aovs(r.aovs_zstd(), in.pixels, in.pass_len);
      else if (!r.aovs_zstd().empty())
        throw WireError("AOV sums for a job without AOVs");
      in.splats = result_splats(r, in.light_tracer, in.splat_limits);
      in.sums = FramePlan::check(result_sums(r, in.pixels * in.planes), in.pass_len, in.planes);
    } catch (const SplatsOverCap&) {  // counted as rejected by merge(), which shortens the job's runs
      b.incoming[k].sums.reset();
      b.incoming[k].splats_over_cap = true;
    } catch (const WireError& e) {  // counted as rejected by merge(), which fails the task
      b.incoming[k].sums.reset();
      b.incoming[k].refused = e.what();
    }
}

bool ResultIntake::shorten_runs(const v1::TaskResult& result, double now, Effects& fx) {
  const Lease* l = p_.leases.live(result.task_id());
  if (!l || l->worker != result.worker_id() || l->check || l->pass_count <= 1) return false;
  Job* job = p_.jobs.find_job(l->job);
  if (!job || !job->live()) return false;
  // Half the run that did not fit, for every later task of the job; this run is ready
  // again now rather than when its lease expires (leased again whole, it would fail again).
  job->max_run = std::min(job->max_run, std::max<uint32_t>(1, l->pass_count / 2));
  p_.leasing.end(result.task_id(), true, now);
  fx.changed = true;
  return true;
}

void ResultIntake::refuse(const v1::TaskResult& result, const std::string& why, double now, Effects& fx) {
  Lease* l = p_.leases.live(result.task_id());
  if (!l || l->worker != result.worker_id() || l->check || l->refused || p_.verifier.quarantined(l->worker)) return;
  Job* job = p_.jobs.find_job(l->job);
  const WorkerInfo* w = p_.workers.find(result.worker_id());
  if (!job || !w || !job->live() || !still_wanted(*l, *job)) return;  // (decode ran without the lock)
  l->refused = true;
  p_.lifecycle.task_failed(*job, *w, refusal(why), now, fx);
}

void ResultIntake::merge(Batch& b, size_t first, size_t last, double now, Effects& fx) {
  for (size_t k = first; k < last; ++k) {
    Incoming& in = b.incoming[k];
    if (!in.sums) {
      ++p_.counters.results_rejected;
      // A run too long is shortened; a single pass past the cap is refused like any other.
      if (in.splats_over_cap) in.refused = "splats past the most a result may carry";
      if (!in.splats_over_cap || !shorten_runs(*b.results[in.index], now, fx))
        refuse(*b.results[in.index], in.refused, now, fx);
      b.acks[in.index].set_refused(refusal(in.refused));
      continue;
    }
    const v1::TaskResult& result = *b.results[in.index];
    const std::optional<Lease> lease = wanted(result, b.acks[in.index]);
    if (!lease || lease->check) continue;
    const std::shared_ptr<Job> shared = p_.jobs.shared(lease->job);
    Job& job = *shared;
    const auto t0 = std::chrono::steady_clock::now();
    uint64_t added = 0;
    if (job.plan.merge(lease->tile, lease->pass, *in.sums, lease->pass_count, &added) != FramePlan::Merge::kMerged) {
      ++p_.counters.results_rejected;
      continue;
    }
    if (in.aovs_wanted) job.plan.add_aovs(lease->tile, in.aovs);  // fits: decoded for this tile's size
    // Digested (and looked at) before they move into the frame's splats.
    const uint64_t digest =
        lease->task ? sums_digest(in.sums->sums(), in.aovs_wanted ? &in.aovs : nullptr, &in.splats) : 0;
    const bool lit = !lease->probation || shows_light(in.sums->sums(), in.splats);
    if (!in.splats.empty()) job.splats.add(lease->tile, lease->pass, std::move(in.splats));
    p_.counters.merge_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    p_.counters.samples_merged += added;
    ++p_.counters.results_merged;
    // Whichever copy of the task arrived first won; every lease on this (tile, pass) ends
    // (kept known, so a repeat of this result is recognised as a duplicate).
    // (A live lease of this (tile, pass) is the tile's first lease or its backup.)
    // A probation task served, unless its result was black: a wrong scale of zero is zero, so
    // it proves nothing of its worker; its lease's end then gives the probation back.
    if (Lease* merged = p_.leases.live(result.task_id())) merged->probation = merged->probation && !lit;
    p_.leasing.end_tile(job, lease->tile, now);
    // The tile's ended leases whose passes are merged now: their ids alone from here on.
    p_.leases.forget_merged(job.id(), lease->tile, [&](const Lease& l) { return still_wanted(l, job); });
    job.merged_by[result.worker_id()].push_back(lease->tile);
    if (!job.sequence.empty()) ++p_.jobs.find_sequence(job.sequence)->changes;
    if (lease->task)  // picked for verification: another worker renders it again
      p_.verifier.issue(job, *lease, result.worker_id(), digest, now);
    p_.counters.result_bytes += result.sums_zstd().size();
    p_.counters.splat_bytes += result.splats_zstd().size();
    // The worker's own time, in the histogram only where it is a time at all; its speed
    // counts the samples merged, not those it claims.
    if (std::isfinite(result.render_seconds()) && result.render_seconds() >= 0)
      p_.counters.task_seconds.observe(result.render_seconds());
    p_.workers.record_result(result.worker_id(), added, result.sums_zstd().size() + result.splats_zstd().size(),
                             result.render_seconds(), result.busy_thread_seconds(), result.thread_seconds(), now);
    if (!p_.lifecycle.finish_if_done(job, now, fx) && p_.snapshots.after_merge(job, now)) fx.writes.push_back(shared);
    b.acks[in.index].set_accepted(true);
    fx.changed = true;
  }
}

}  // namespace tessera
