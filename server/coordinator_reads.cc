// The coordinator's answers to clients that read: a job's status, the list, its image, and
// the waits a watcher makes. A job in memory answers under the lock; an archived one
// (archive.h) from its row, without it.
#include <set>

#include "core/util/log.h"
#include "server/archive.h"
#include "server/coordinator.h"
#include "server/image_stream.h"

namespace tessera {

std::optional<v1::JobStatus> Coordinator::archived(const std::string& id) const {
  return with_store([&] { return archived_status(*store_, id); }, "job " + id + ": ");
}

std::optional<StoredJob> Coordinator::archived_change(const std::string& id, const std::string& requester, bool any,
                                                      const char* verb) const {
  {
    MutexLock lock(mu_);
    if (jobs_.knows(id)) return std::nullopt;
  }
  return with_store([&] { return archived_for_change(*store_, id, requester, any, verb); });
}

v1::JobStatus Coordinator::status(const std::string& id, bool with_tiles, TileRange range, FrameRange frames) const {
  return find(
      id,
      [&]() TESSERA_REQUIRES(mu_) { return job_status(jobs_, leases_, id, with_tiles, clock_->now(), range, frames); },
      [&] {
        std::optional<v1::JobStatus> s = archived(id);
        if (s && with_tiles) add_archived_tiles(*s, range);
        if (s && s->frames_total() > 0) page_frames(*s, frames);
        return s;
      });
}

std::vector<v1::JobStatus> Coordinator::list() const {
  MutexLock lock(mu_);
  return job_list(jobs_, leases_, clock_->now());
}

std::vector<v1::JobStatus> Coordinator::statuses(const std::vector<StoredJob>& rows) const {
  std::vector<std::optional<v1::JobStatus>> got(rows.size());
  {
    MutexLock lock(mu_);  // jobs in memory: one lock for them all
    for (size_t i = 0; i < rows.size(); ++i)
      if (rows[i].summary.empty() && jobs_.knows(rows[i].meta.id))
        got[i] = job_summary(jobs_, leases_, rows[i].meta.id, clock_->now());
  }
  std::vector<v1::JobStatus> out;
  for (size_t i = 0; i < rows.size(); ++i) {
    if (!rows[i].summary.empty())
      got[i] = archived_status(rows[i], false);
    else if (!got[i])
      got[i] = archived(rows[i].meta.id);  // archived since the rows were read (or not yet acknowledged: left out)
    if (!got[i]) continue;
    got[i]->clear_frames();  // (as job_summary: a list counts a sequence's frames, GetJob lists them)
    out.push_back(std::move(*got[i]));
  }
  return out;
}

v1::JobList Coordinator::list(uint32_t page_size, const std::string& page_token) const {
  const uint64_t after = page_after(page_token);
  const size_t n = page_size == 0 ? kMaxPage : std::min(page_size, kMaxPage);  // (never every row at once)
  v1::JobList out;
  std::vector<StoredJob> rows = with_store([&] {
    out.set_total(store_->count());
    return store_->page(after, n + 1);  // one more: is there a next page?
  });
  if (rows.size() > n) {
    rows.pop_back();
    out.set_next_page_token(std::to_string(rows.back().meta.seq));
  }
  for (v1::JobStatus& s : statuses(rows)) *out.add_jobs() = std::move(s);
  return out;
}

std::vector<v1::JobStatus> Coordinator::recent(size_t n) const {
  std::vector<v1::JobStatus> newest = statuses(with_store([&] { return store_->newest(n); })), out;
  std::set<std::string> have;
  for (const v1::JobStatus& s : newest) have.insert(s.id());
  for (v1::JobStatus& s : list())  // live ones submitted before those (in memory, in submission order)
    if (job_live(s.state()) && !have.count(s.id())) out.push_back(std::move(s));
  for (v1::JobStatus& s : newest) out.push_back(std::move(s));
  return out;
}

std::array<uint64_t, 5> Coordinator::job_counts() const {
  std::lock_guard<std::mutex> counts(archive_counts_mu_);  // no job between the store and memory
  std::array<uint64_t, 5> n{};
  try {
    n = store_->archived_states();
  } catch (const std::exception& e) {  // (metrics go on with what memory has)
    spdlog::warn("counting archived jobs: {}", e.what());
  }
  for (const v1::JobStatus& s : list()) ++n[std::min<size_t>(4, size_t(s.state()))];
  return n;
}

std::string Coordinator::current_image(const std::string& id, std::optional<int> frame, ImageStreamHeader* header) {
  std::shared_ptr<Job> job;
  bool live = false, writer = false;
  uint64_t merges = 0;  // the film's version as asked
  const std::optional<std::string> whose = find(
      id,
      [&]() TESSERA_REQUIRES(mu_) -> std::optional<std::string> {
        if (const auto gone = jobs_.left_frame(id, frame)) {  // DONE, its image on disk holds its whole film
          header->frame_passes_done = uint32_t(gone->sequence->settings.passes().size());
          header->final = true;
          return gone->id();
        }
        job = jobs_.shared(jobs_.frame_job(id, frame).id());
        live = job->live();
        merges = job->plan.merges();
        // A live job gets its latest image. An ended job's film no longer changes, and the
        // image must hold all of it: the merge (or cancel) that ended the job asks for its
        // last image, which may still be being written, so a client that saw the end can
        // get here first.
        if (!Snapshotter::image_current(*job, live, merges)) writer = snapshotter_.request(*job, true, !live);
        return std::nullopt;
      },
      [&]() -> std::optional<std::optional<std::string>> {
        std::optional<std::string> who = with_store([&] { return archived_image(*store_, id, frame, header); });
        if (who) return who;
        return std::nullopt;
      });
  if (whose) return *whose;
  if (writer) write(job);
  MutexLock lock(mu_);
  await([&] { return Snapshotter::image_current(*job, live, merges) || !job->snaps.writing; });
  if (!Snapshotter::image_current(*job, live, merges))
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + job->id() + ": its image could not be written (" + job->image_error +
                           "); the samples are kept and the write is retried");
  header->frame_passes_done = job->snaps.image_frame_passes;
  header->final = !live && job->end_recorded;  // ended durably (and the image holds the whole film)
  return job->id();
}

namespace {
// A final image is checked before it is served: a damaged one is an error, not a download.
void require_intact(const ImageSink& sink, const std::string& job, const ImageStreamHeader& h) {
  if (h.final && !sink.intact(job))
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + job +
                           ": its final image on the coordinator is damaged or cut short (its log says how); "
                           "nothing was sent");
}
}  // namespace

v1::Image Coordinator::image(const std::string& id, bool exr, bool png, std::optional<int> frame) {
  ImageStreamHeader h;
  const std::string job = current_image(id, frame, &h);
  require_intact(*sink_, job, h);
  return whole_image(*sink_, job, exr, png, h);
}

void Coordinator::image_chunks(const v1::FetchImageRequest& req,
                               const std::function<bool(const v1::ImageChunk&)>& write) {
  ImageStreamHeader h;
  const std::string job = current_image(req.id(), req.has_frame() ? std::optional(req.frame()) : std::nullopt, &h);
  const std::unique_ptr<ImageSink::Reader> file = sink_->open(job);
  if (!file) throw RequestError(RequestError::Code::kFailedPrecondition, "job " + job + " has no image file");
  require_intact(*sink_, job, h);
  stream_image(*file, req, h, options_.image_chunk_bytes, write);
}

// ---- waiting ----

v1::JobStatus Coordinator::wait_for_change(const std::string& id, uint64_t last_samples, double timeout) const {
  {
    MutexLock lock(mu_);
    if (jobs_.knows(id)) {
      const JobProgress since = job_progress(jobs_, id);
      if (since.samples == last_samples)  // (else the caller's status is behind already)
        await([&]() TESSERA_REQUIRES(
                  mu_) { return since.ended || !jobs_.knows(id) || !(job_progress(jobs_, id) == since); },
              timeout);
      if (jobs_.knows(id)) return job_status(jobs_, leases_, id, false, clock_->now());
    }
  }
  return status(id, false);  // archived: ended
}

bool Coordinator::wait_for_end(const std::string& id, double timeout) const {
  {
    MutexLock lock(mu_);
    if (jobs_.knows(id))  // (one that leaves memory has ended: it is archived, or deleted)
      return await([&]() TESSERA_REQUIRES(mu_) { return !jobs_.knows(id) || job_progress(jobs_, id).ended; }, timeout);
  }
  return !job_live(status(id, false).state());
}

}  // namespace tessera
