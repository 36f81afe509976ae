#include "server/auth.h"

#include <openssl/evp.h>

#include <sstream>

#include "core/io/files.h"
#include "server/credentials.h"
#include "server/secrets.h"

namespace tessera {
namespace {

std::optional<Role> parse_role(const std::string& s) {
  if (s == "viewer") return Role::kViewer;
  if (s == "client") return Role::kClient;
  if (s == "worker") return Role::kWorker;
  if (s == "admin") return Role::kAdmin;
  if (s == "enrol") return Role::kEnrol;
  return std::nullopt;
}

// Standard padded base64 (what HTTP Basic authentication sends); empty if malformed.
std::string base64_decode(std::string_view in) {
  if (in.empty() || in.size() % 4 != 0 || in.size() > 4096) return {};
  std::string out(in.size() / 4 * 3, '\0');
  const int n = EVP_DecodeBlock(reinterpret_cast<unsigned char*>(out.data()),
                                reinterpret_cast<const unsigned char*>(in.data()), int(in.size()));
  if (n < 0) return {};
  size_t padding = 0;  // EVP_DecodeBlock counts the bytes '=' stands for
  while (padding < 2 && in[in.size() - 1 - padding] == '=') ++padding;
  out.resize(size_t(n) - padding);
  return out;
}

}  // namespace

const char* role_name(Role role) {
  switch (role) {
    case Role::kViewer:
      return "viewer";
    case Role::kClient:
      return "client";
    case Role::kWorker:
      return "worker";
    case Role::kAdmin:
      return "admin";
    case Role::kEnrol:
      return "enrol";
  }
  return "?";
}

Authenticator Authenticator::from_file(const std::string& path) {
  std::string text;
  try {
    text = read_file_bytes(path);
  } catch (const std::runtime_error& e) {
    throw AuthConfigError(e.what());
  }
  return from_text(text, path);
}

Authenticator Authenticator::from_text(const std::string& text, const std::string& where) {
  Authenticator a;
  std::istringstream lines(text);
  std::string line;
  for (int n = 1; std::getline(lines, line); ++n) {
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream words(line);
    std::string role, name, token, extra;
    if (!(words >> role)) continue;  // blank or comment
    const std::string at = where + ":" + std::to_string(n) + ": ";
    if (!(words >> name >> token) || (words >> extra)) throw AuthConfigError(at + "expected ROLE NAME TOKEN");
    const std::optional<Role> r = parse_role(role);
    if (!r) throw AuthConfigError(at + "unknown role '" + role + "' (viewer, client, worker, enrol or admin)");
    if (token.size() < kMinTokenLength)
      throw AuthConfigError(at + "token shorter than " + std::to_string(kMinTokenLength) + " characters");
    if (!a.tokens_.emplace(sha256(token), Principal{name, *r}).second)
      throw AuthConfigError(at + "the same token appears twice");
  }
  if (a.tokens_.empty()) throw AuthConfigError(where + ": no tokens");
  return a;
}

std::optional<Principal> Authenticator::lookup(std::string_view token, std::string* quarantined) const {
  if (!enabled()) return Principal{"", Role::kAdmin};
  if (token.empty()) return std::nullopt;
  // Looked up by digest: how long a comparison takes says nothing about the token.
  const std::string digest = sha256(token);
  if (auto it = tokens_.find(digest); it != tokens_.end()) return it->second;
  if (!book_) return std::nullopt;
  const std::optional<CredentialBook::Holder> h = book_->find(digest);
  if (!h) return std::nullopt;
  if (!h->quarantined) return Principal{h->name, Role::kWorker, true};
  if (quarantined) *quarantined = "worker '" + h->name + "' is quarantined: " + h->why;
  return std::nullopt;
}

std::optional<Principal> Authenticator::authenticate(std::string_view token) const { return lookup(token, nullptr); }

std::string Authenticator::token_from_header(std::string_view v) {
  auto strip = [](std::string_view s) {
    while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\r')) s.remove_suffix(1);
    return s;
  };
  v = strip(v);
  if (v.substr(0, 7) == "Bearer ") return std::string(strip(v.substr(7)));
  if (v.substr(0, 6) == "Basic ") {
    const std::string user_pass = base64_decode(strip(v.substr(6)));
    const size_t colon = user_pass.find(':');
    return colon == std::string::npos ? std::string() : user_pass.substr(colon + 1);
  }
  return {};
}

Authenticator::Check Authenticator::check(std::string_view authorization, Action action) const {
  const std::string token = token_from_header(authorization);
  std::string quarantined;
  const std::optional<Principal> p = lookup(token, &quarantined);
  if (!quarantined.empty()) return {Check::kDenied, {}, quarantined};
  if (!p)
    return {
        Check::kUnauthenticated,
        {},
        token.empty() ? "this coordinator needs an access token" : "the access token is not known to this coordinator"};
  if (!allows(p->role, action))
    return {Check::kDenied, {}, std::string("a ") + role_name(p->role) + " token may not do this"};
  return {Check::kAllowed, *p, ""};
}

bool Authenticator::allows(Role role, Action action) {
  switch (role) {
    case Role::kAdmin:
      return true;
    case Role::kClient:
      return action != Action::kWork && action != Action::kEnrol;
    case Role::kViewer:
      return action == Action::kRead;
    case Role::kWorker:
      return action == Action::kWork;
    case Role::kEnrol:
      return action == Action::kEnrol;
  }
  return false;
}

}  // namespace tessera
