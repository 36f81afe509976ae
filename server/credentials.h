// Workers' own credentials (docs/security.md, "Enrolment"). A worker presents an enrolment
// token (role "enrol") once, with its name, and gets a credential of its own: an access
// token of role worker for that name only. From then on it is an identity of its own: one
// live registration (registering again replaces the last), and a quarantine that is its
// own, kept across restarts, where a shared worker token could only be quarantined for
// every worker that holds it. Credentials are kept as SHA-256 digests in the JobStore.
// Thread-safe; its lock is a leaf (a store write may happen under it).
#pragma once

#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/util/mutex.h"
#include "server/job_store.h"

namespace tessera {

class CredentialBook {
 public:
  static constexpr double kIdleSeconds = 3600;             // unused this long: forgotten
  static constexpr double kQuarantineSeconds = 7 * 86400;  // a quarantined name's time out
  static constexpr size_t kMaxNameLength = 128;

  // Takes up what `store` kept (idle times count from now).
  explicit CredentialBook(JobStore& store);

  // A new credential for `name` (letters, digits and . _ - : @), enrolled by the enrolment
  // token named `enroller`, which may hold at most `max_per_enroller` at once. The name's
  // earlier credential, if any, stops working. Durable when it returns. Throws RequestError:
  // kInvalidArgument (the name), kPermissionDenied (a quarantined name),
  // kResourceExhausted (the bound, naming --max-workers-per-token).
  std::string enrol(const std::string& name, const std::string& enroller, size_t max_per_enroller);

  struct Holder {
    std::string name;
    bool quarantined = false;
    std::string why;  // the quarantine's
  };
  // Who holds the credential whose SHA-256 is `digest` (its use is recorded); nothing if
  // it is not one of ours.
  std::optional<Holder> find(const std::string& digest);
  // The name's credential is refused from now on, and the name may not enrol again for
  // kQuarantineSeconds. Errors writing it are logged (the quarantine holds in memory).
  void quarantine(const std::string& name, const std::string& why);
  // Forgets credentials unused for kIdleSeconds and quarantines past their time; returns
  // how many went. (On the reaper's tick, once a minute.)
  size_t expire();
  size_t size() const;
  std::vector<StoredCredential> list() const;

 private:
  struct Entry {
    StoredCredential stored;
    double last_used = 0;
  };
  size_t expire_locked(double now) TESSERA_REQUIRES(mu_);
  JobStore& store_;
  mutable Mutex mu_;
  std::map<std::string, Entry> by_name_ TESSERA_GUARDED_BY(mu_);
  std::map<std::string, std::string> name_by_digest_ TESSERA_GUARDED_BY(mu_);
};

}  // namespace tessera
