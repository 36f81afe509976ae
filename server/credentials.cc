#include "server/credentials.h"

#include <algorithm>

#include "core/util/log.h"
#include "server/request_error.h"
#include "server/secrets.h"

namespace tessera {
namespace {

bool valid_name(const std::string& n) {
  return !n.empty() && n.size() <= CredentialBook::kMaxNameLength && std::all_of(n.begin(), n.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
           c == '-' || c == ':' || c == '@';
  });
}

}  // namespace

CredentialBook::CredentialBook(JobStore& store) : store_(store) {
  const double now = store_.wall();
  MutexLock lock(mu_);
  for (StoredCredential& c : store_.credentials()) {
    name_by_digest_[c.digest] = c.name;
    const std::string name = c.name;
    by_name_[name] = {std::move(c), now};
  }
}

std::string CredentialBook::enrol(const std::string& name, const std::string& enroller, size_t max_per_enroller) {
  if (!valid_name(name))
    throw RequestError(
        RequestError::Code::kInvalidArgument,
        "a worker name to enrol is 1 to " + std::to_string(kMaxNameLength) + " letters, digits and . _ - : @");
  const double now = store_.wall();
  MutexLock lock(mu_);
  expire_locked(now);  // enrolments are rare; what expired makes room
  auto it = by_name_.find(name);
  if (it != by_name_.end()) {
    const StoredCredential& old = it->second.stored;
    if (old.quarantined_at > 0)
      throw RequestError(RequestError::Code::kPermissionDenied,
                         "worker '" + name + "' is quarantined (" + old.why + "); it may not enrol again");
    if (old.enroller != enroller)
      throw RequestError(RequestError::Code::kPermissionDenied,
                         "worker name '" + name + "' is enrolled by another enrolment token");
  } else if (size_t(std::count_if(by_name_.begin(), by_name_.end(), [&](const auto& e) {
               return e.second.stored.enroller == enroller;
             })) >= max_per_enroller) {
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "enrolment token '" + enroller + "' has its " + std::to_string(max_per_enroller) +
                           " workers (--max-workers-per-token; a credential unused for an hour is forgotten)");
  }
  const std::string credential = random_hex(24);
  StoredCredential c{name, sha256(credential), enroller, now, 0, ""};
  store_.put_credential(c);  // durable before the worker may use it
  if (it != by_name_.end()) name_by_digest_.erase(it->second.stored.digest);
  name_by_digest_[c.digest] = name;
  by_name_[name] = {std::move(c), now};
  return credential;
}

std::optional<CredentialBook::Holder> CredentialBook::find(const std::string& digest) {
  MutexLock lock(mu_);
  auto d = name_by_digest_.find(digest);
  if (d == name_by_digest_.end()) return std::nullopt;
  Entry& e = by_name_.at(d->second);
  e.last_used = store_.wall();
  return Holder{e.stored.name, e.stored.quarantined_at > 0, e.stored.why};
}

void CredentialBook::quarantine(const std::string& name, const std::string& why) {
  MutexLock lock(mu_);
  auto it = by_name_.find(name);
  if (it == by_name_.end() || it->second.stored.quarantined_at > 0) return;
  it->second.stored.quarantined_at = store_.wall();
  it->second.stored.why = why;
  try {
    store_.put_credential(it->second.stored);
  } catch (const std::exception& e) {
    spdlog::error("worker '{}': recording its quarantine: {} (it holds until the coordinator stops)", name, e.what());
  }
}

size_t CredentialBook::expire() {
  const double now = store_.wall();
  MutexLock lock(mu_);
  return expire_locked(now);
}

size_t CredentialBook::expire_locked(double now) {
  std::vector<std::string> gone;
  for (const auto& [name, e] : by_name_) {
    const double q = e.stored.quarantined_at;
    if (q > 0 ? now - q >= kQuarantineSeconds : now - e.last_used >= kIdleSeconds) gone.push_back(name);
  }
  if (gone.empty()) return 0;
  try {
    store_.remove_credentials(gone);
  } catch (const std::exception& e) {
    spdlog::error("forgetting {} unused worker credentials: {}", gone.size(), e.what());
    return 0;
  }
  for (const std::string& name : gone) {
    name_by_digest_.erase(by_name_.at(name).stored.digest);
    by_name_.erase(name);
  }
  return gone.size();
}

size_t CredentialBook::size() const {
  MutexLock lock(mu_);
  return by_name_.size();
}

std::vector<StoredCredential> CredentialBook::list() const {
  MutexLock lock(mu_);
  std::vector<StoredCredential> out;
  for (const auto& [name, e] : by_name_) out.push_back(e.stored);
  return out;
}

}  // namespace tessera
