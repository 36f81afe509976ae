#include "server/verifier.h"

#include <algorithm>
#include <set>

#include "core/util/log.h"
#include "server/result_intake.h"
#define XXH_INLINE_ALL  // header only: nothing to link
#include <xxhash.h>

namespace tessera {

uint64_t sums_digest(const std::vector<PixelSums>& sums, const std::vector<AovSums>* aovs,
                     const std::vector<SplatRecord>* splats) {
  XXH3_state_t st;
  XXH3_64bits_reset(&st);
  for (const PixelSums& p : sums) {
    const double v[4] = {p.r, p.g, p.b, p.lum2};
    XXH3_64bits_update(&st, v, sizeof v);
    XXH3_64bits_update(&st, &p.n, sizeof p.n);
  }
  if (aovs) {
    static_assert(sizeof(AovSums) == 72, "AovSums has no padding: its bytes are its value");
    XXH3_64bits_update(&st, aovs->data(), aovs->size() * sizeof(AovSums));
  }
  if (splats && !splats->empty()) {
    static_assert(sizeof(SplatEntry) == 40, "SplatEntry: index, padding (zero), sums");
    for (const SplatRecord& r : *splats) {
      const uint64_t counts[3] = {r.paths, r.odd_paths, r.entries.size()};
      XXH3_64bits_update(&st, counts, sizeof counts);
      for (const SplatEntry& e : r.entries) {
        XXH3_64bits_update(&st, &e.index, sizeof e.index);
        XXH3_64bits_update(&st, e.v, sizeof e.v);
      }
    }
  }
  return XXH3_64bits_digest(&st);
}

void Verifier::issue(Job& job, const Lease& lease, uint64_t worker, uint64_t digest, double now) {
  Check c;
  c.job = job.id();
  c.tile = lease.tile;
  c.pass = lease.pass;
  c.task = lease.task;
  c.first_worker = worker;
  if (const WorkerInfo* w = workers_.find(worker)) c.first_serial = w->serial;
  c.digest = digest;
  c.since = now;
  checks_.add(std::move(c));
  ++job.pending_checks;
  ++counters_.checks_issued;
}

void Verifier::lease_checks(WorkerInfo& worker, uint32_t max, double now, v1::GetTaskResponse& out) {
  for (auto& [id, c] : checks_.all()) {  // few, and a job waits for its checks to end
    if (uint32_t(out.tasks_size()) >= max) break;
    if (c.lease || !may_check(c, worker)) continue;
    // Nor to a worker resting from the job (its task of it failed lately: a check would too).
    if (const Job* job = jobs_.find_job(c.job); job && job->resting(worker.identity(), now)) continue;
    v1::Task* task = out.add_tasks();
    *task = *c.task;
    task->set_task_id(leasing_.grant_check(id, worker, now));
  }
}

bool Verifier::may_check(const Check& c, const WorkerInfo& worker) {
  if (worker.id == c.first_worker) return false;
  // Its first worker's registration ended (without a catch: that drops its checks). A
  // worker registered since may be the same process under a new id (a shared token tells
  // them apart by nothing), which would pass its own result: only those registered before it.
  return workers_.find(c.first_worker) || worker.serial < c.first_serial;
}

std::optional<Check> Verifier::pending(uint64_t check, uint64_t task_id) const {
  const auto& all = checks_.all();
  auto it = all.find(check);
  if (it == all.end() || it->second.lease != task_id) return std::nullopt;
  return it->second;
}

std::optional<uint64_t> result_digest(const v1::TaskResult& result, const Check& check, std::string* why) {
  try {
    const Rect tile = from_proto(check.task->tile());
    const size_t pixels = size_t(tile.area());
    const RenderSettings settings = from_proto(check.task->settings());
    const size_t planes = settings.sum_planes();
    const std::vector<SplatRecord> splats = ResultIntake::result_splats(
        result, settings.light_tracer, ResultIntake::splat_limits(settings, tile, task_passes(*check.task, settings)));
    if (!check.task->settings().aovs()) return sums_digest(result_sums(result, pixels), nullptr, &splats);
    const std::vector<AovSums> aovs = decode_aovs(result.aovs_zstd(), pixels, RenderSettings::kMaxSpp);
    return sums_digest(result_sums(result, pixels * planes), &aovs, &splats);
  } catch (const WireError& e) {
    *why = e.what();
    return std::nullopt;
  }
}

Verifier::Verdict Verifier::judge(const Check& c, uint64_t digest, uint64_t checker, const Referee& referee) {
  Verdict v;
  v.same = digest == c.digest;
  if (v.same) return v;
  // Two workers differ: this process renders the task too, and whoever differs from it is
  // quarantined (both, if all three differ). Rare, so done here, outside the lock.
  try {
    const RefereeRender r = referee(*c.task);
    const uint64_t ours = sums_digest(r.sums, r.aovs.empty() ? nullptr : &r.aovs, &r.splats);
    if (ours != c.digest) v.liars.push_back(c.first_worker);
    if (ours != digest) v.liars.push_back(checker);
    v.why = "job " + c.job + " tile " + std::to_string(c.tile) + " pass " + std::to_string(c.pass) +
            ": its sums differ from the coordinator's render of the same task";
  } catch (const std::exception& e) {
    spdlog::error("check of job {} tile {}: cannot render it here: {}", c.job, c.tile, e.what());
  }
  return v;
}

bool Verifier::decide(uint64_t check, uint64_t task_id, uint64_t checker, const Verdict& v, double now, Effects& fx) {
  if (!v.same) ++counters_.check_mismatches;
  const std::optional<Check> c = pending(check, task_id);
  if (!c) return false;  // moot meanwhile
  drop(check, false, now);
  if (v.same) ++counters_.checks_passed;
  for (uint64_t w : v.liars) quarantine(w, v.why, now, fx);
  if (Job* job = jobs_.find_job(c->job)) lifecycle_.finish_if_done(*job, now, fx);
  fx.changed = true;
  return std::find(v.liars.begin(), v.liars.end(), checker) == v.liars.end();
}

void Verifier::drop(uint64_t check, bool skipped, double now) {
  Check* c = checks_.find(check);
  if (!c) return;
  if (c->lease) leasing_.end(c->lease, false, now);
  if (Job* job = jobs_.find_job(c->job); job && job->pending_checks > 0) --job->pending_checks;
  counters_.checks_skipped += skipped;
  checks_.erase(check);
}

void Verifier::skip_stale(double now, Effects& fx) {
  std::set<std::string> touched;
  std::vector<uint64_t> stale;
  for (const auto& [id, c] : checks_.all()) {
    const size_t others = workers_.find(c.first_worker) ? workers_.size() - 1 : workers_.count_before(c.first_serial);
    if (c.lease == 0 && (others == 0 || now - c.since > 2 * lease_seconds_)) stale.push_back(id);
  }
  for (uint64_t id : stale) {
    touched.insert(checks_.find(id)->job);
    drop(id, true, now);
  }
  for (const std::string& id : touched)
    if (Job* job = jobs_.find_job(id)) lifecycle_.finish_if_done(*job, now, fx);
}

std::string Verifier::ended_flag(uint32_t tiles, const std::string& worker, bool frames) {
  return frames ? std::to_string(tiles) + " tiles of finished frames hold results of worker " + worker +
                      ", quarantined after those frames ended (its results differed from the same tasks rendered "
                      "elsewhere): submit the job again for images without them"
                : std::to_string(tiles) + " tiles hold results of worker " + worker +
                      ", quarantined after the job ended (its results differed from the same tasks rendered "
                      "elsewhere): submit the job again for an image without them";
}

void Verifier::flag_ended(Job& job, const std::string& flag, Effects& fx) {
  auto add = [&](std::string& error, const std::string& what) { error += (error.empty() ? "" : "; ") + what; };
  add(job.error, flag);
  if (job.sequence.empty()) {
    fx.rows.push_back({job.id(), job.state(), job.error, job.finished_at - job.started});
    return;
  }
  // A frame has no row: its sequence carries the flag (recorded with its end, or now if it
  // has ended).
  if (Sequence* s = jobs_.find_sequence(job.sequence))
    flag_sequence(*s, "frame " + std::to_string(s->frames[job.frame_index]) + ": " + flag, fx);
}

void Verifier::flag_sequence(Sequence& s, const std::string& flag, Effects& fx) {
  s.error += (s.error.empty() ? "" : "; ") + flag;
  if (!s.live()) fx.rows.push_back({s.id(), s.state(), s.error, s.finished_at - s.started});
}

void Verifier::quarantine(uint64_t worker, const std::string& why, double now, Effects& fx) {
  std::string name = std::to_string(worker);
  if (const WorkerInfo* w = workers_.find(worker)) {
    name = "'" + w->name + "' (" +
           (w->principal.empty() ? "" : (w->enrolled ? "enrolled as '" : "token '") + w->principal + "', ") + name +
           ")";
    if (w->enrolled) fx.credentials_quarantined.push_back({w->principal, why});
  }
  if (!checks_.quarantine(worker)) return;
  ++counters_.workers_quarantined;
  const WorkerInfo* w = workers_.find(worker);
  fx.events.push_back(
      {0, 0, "worker.quarantined", "", w ? w->name : std::to_string(worker), w ? w->principal : "", why});
  leasing_.end_worker(worker, now);
  // What it merged is rendered again: every tile of a live job it added sums to starts
  // over (a tile's passes build on each other). An ended job is flagged.
  std::set<std::string> flagged;  // stills and sequences
  for (const auto& [id, job] : jobs_.jobs()) {
    auto mine = job->merged_by.find(worker);
    if (mine == job->merged_by.end()) continue;
    std::set<uint32_t> tiles(mine->second.begin(), mine->second.end());
    job->merged_by.erase(mine);
    if (job->live()) {
      ++job->resets;
      // Its splats landed anywhere in the frame, among everyone's: the whole frame starts over.
      if (job->splats.any()) {
        job->splats.reset();
        for (uint32_t t = 0; t < job->plan.tile_count(); ++t) tiles.insert(t);
      }
      for (uint32_t t : tiles) {
        leasing_.end_tile(*job, t, now);
        job->plan.reset_tile(t);
        ++job->tile_resets[t];  // its results leased before now are refused
        ++counters_.tiles_rendered_again;
      }
      std::vector<uint64_t> moot;  // checks of those tiles
      for (const auto& [check, c] : checks_.all())
        if (c.job == id && tiles.count(c.tile)) moot.push_back(check);
      for (uint64_t check : moot) drop(check, false, now);
    } else {
      // Its splats (a frame tracing light paths) landed anywhere: every tile holds them.
      const bool splats = job->plan.settings().light_tracer != RenderSettings::LightTracer::kOff;
      const uint32_t held = splats ? job->plan.tile_count() : uint32_t(tiles.size());
      if (job->state() == v1::JobStatus::DONE) {
        flag_ended(*job, ended_flag(held, name, false), fx);
      } else {  // CANCELLED or FAILED: a requeue renders those tiles again (it kept them before)
        for (uint32_t t = 0; t < job->plan.tile_count(); ++t)
          if (splats || tiles.count(t)) job->tainted.insert(t);
        flag_ended(*job,
                   std::to_string(held) + " tiles hold results of worker " + name +
                       ", quarantined after the job ended (its results differed from the same tasks rendered "
                       "elsewhere): a requeue renders them again",
                   fx);
      }
      flagged.insert(job->sequence.empty() ? id : job->sequence);
    }
  }
  // Frames that left memory (JobTable::let_go) flag their sequence.
  for (const auto& [id, s] : jobs_.sequences()) {
    auto mine = s->left_merged_by.find(worker);
    if (mine == s->left_merged_by.end()) continue;
    flag_sequence(*s, ended_flag(mine->second, name, true), fx);
    s->left_merged_by.erase(mine);
    flagged.insert(id);
  }
  // Archived jobs (archive.h) are flagged in their rows; those flagged here are not again.
  fx.flags.push_back({worker, name, std::move(flagged)});
  workers_.remove(worker);
  fx.changed = true;
}

}  // namespace tessera
