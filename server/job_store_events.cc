// SqliteJobStore's table of events (events.h): the newest kMaxEvents, by id.
#include <algorithm>

#include "server/job_store.h"
#include "server/sqlite_statement.h"

namespace tessera {

void SqliteJobStore::append_events(std::vector<Event>& events) {
  if (events.empty()) return;
  MutexLock lock(mu_);
  transaction([&] {
    for (Event& e : events) {
      Statement(db_, "INSERT INTO events(time, kind, job, worker, who, detail) VALUES(?1, ?2, ?3, ?4, ?5, ?6)")
          .real(1, e.time)
          .text(2, e.kind)
          .text(3, e.job)
          .text(4, e.worker)
          .text(5, e.who)
          .text(6, e.detail)
          .step();
      e.id = uint64_t(sqlite3_last_insert_rowid(db_));
    }
    // The oldest go: a range of the primary key, cheap at every append.
    Statement(db_, "DELETE FROM events WHERE id <= ?1")
        .integer(1, int64_t(events.back().id) - int64_t(kMaxEvents))
        .step();
  });
}

std::vector<Event> SqliteJobStore::events(const std::string& job, uint64_t after, size_t limit, bool newest) const {
  MutexLock lock(mu_);
  std::vector<Event> out;
  // With `newest`, the last `limit` by id, read backwards and turned round.
  std::string sql = "SELECT id, time, kind, job, worker, who, detail FROM events WHERE id > ?1";
  if (!job.empty()) sql += " AND job = ?2";
  sql += newest ? " ORDER BY id DESC LIMIT ?3" : " ORDER BY id LIMIT ?3";
  Statement q(db_, sql.c_str());
  q.integer(1, int64_t(after)).integer(3, int64_t(limit));
  if (!job.empty()) q.text(2, job);
  while (q.step())
    out.push_back({uint64_t(q.column_int(0)), q.column_real(1), q.column_text(2), q.column_text(3), q.column_text(4),
                   q.column_text(5), q.column_text(6)});
  if (newest) std::reverse(out.begin(), out.end());
  return out;
}

}  // namespace tessera
