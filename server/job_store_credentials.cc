// SqliteJobStore's table of workers' credentials (credentials.h): one row a worker name.
#include "server/job_store.h"
#include "server/sqlite_statement.h"

namespace tessera {

void SqliteJobStore::put_credential(const StoredCredential& c) {
  MutexLock lock(mu_);
  Statement(db_,
            "INSERT OR REPLACE INTO credentials(name, digest, enroller, created, quarantined_at, why) "
            "VALUES(?1, ?2, ?3, ?4, ?5, ?6)")
      .text(1, c.name)
      .blob(2, c.digest)
      .text(3, c.enroller)
      .real(4, c.created)
      .real(5, c.quarantined_at)
      .text(6, c.why)
      .step();
}

void SqliteJobStore::remove_credentials(const std::vector<std::string>& names) {
  MutexLock lock(mu_);
  transaction([&] {
    for (const std::string& n : names) Statement(db_, "DELETE FROM credentials WHERE name = ?1").text(1, n).step();
  });
}

std::vector<StoredCredential> SqliteJobStore::credentials() const {
  MutexLock lock(mu_);
  std::vector<StoredCredential> out;
  for (Statement q(db_, "SELECT name, digest, enroller, created, quarantined_at, why FROM credentials"); q.step();)
    out.push_back(
        {q.column_text(0), q.column_text(1), q.column_text(2), q.column_real(3), q.column_real(4), q.column_text(5)});
  return out;
}

}  // namespace tessera
