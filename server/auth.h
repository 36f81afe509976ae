// Who may do what. Tokens with roles, read from a file the operator keeps (never from the
// command line); each gRPC call and HTTP request presents one, and its role decides:
//
//   viewer   read: job status, images, the live page, /api/*, /metrics
//   client   what a viewer may, and submit jobs; cancel, requeue, re-prioritise and delete
//            its own
//   worker   register, lease tasks, fetch scenes, return results; nothing else
//   enrol    enrol workers: each gets a credential of its own (credentials.h), which then
//            acts as a worker token for that worker only
//   admin    everything, including changing or deleting anyone's job
//
// Without a token file every caller is an admin: the coordinator then listens on loopback
// only unless the operator says --insecure (server/main.cc).
#pragma once

#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tessera {

enum class Role { kViewer, kClient, kWorker, kAdmin, kEnrol };
// kCancel: any change to a job after submit; kEnrol: a worker's credential made
enum class Action { kRead, kSubmit, kCancel, kWork, kEnrol };

class CredentialBook;

struct Principal {
  std::string name;  // from the token file (whose jobs are whose), or an enrolled worker's
  Role role = Role::kAdmin;
  bool enrolled = false;  // a worker's own credential, not a token from the file
};

class AuthConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Authenticator {
 public:
  Authenticator() = default;  // open: no tokens, everyone is an admin
  // Lines "ROLE NAME TOKEN" (role: viewer, client, worker or admin; '#' starts a comment).
  // Tokens are kept only as SHA-256 digests. Throws AuthConfigError naming the file and
  // line; a token shorter than kMinTokenLength is refused (guessable).
  static Authenticator from_file(const std::string& path);
  static Authenticator from_text(const std::string& text, const std::string& where);
  static constexpr size_t kMinTokenLength = 16;

  bool enabled() const { return !tokens_.empty(); }
  // Workers' own credentials are looked up in `book` too (after the file's tokens); a
  // quarantined one is refused naming why. The book outlives this.
  void use_credentials(CredentialBook* book) { book_ = book; }
  // The principal a token stands for; nothing if it stands for none. Open: the admin.
  std::optional<Principal> authenticate(std::string_view token) const;
  // The token in an "authorization" header or metadata value: "Bearer T", or HTTP Basic
  // with the token as the password (what a browser asks for).
  static std::string token_from_header(std::string_view value);
  static bool allows(Role role, Action action);

  // Who presents `authorization` (a header or metadata value, possibly empty) and whether
  // its role may do `action`: the one check behind every gRPC call and HTTP request.
  struct Check {
    enum Outcome { kAllowed, kUnauthenticated, kDenied } outcome = kUnauthenticated;
    Principal who;    // when allowed
    std::string why;  // when not: for the caller, naming what is missing
  };
  Check check(std::string_view authorization, Action action) const;

 private:
  // authenticate(), saying in `quarantined` (if given) why a quarantined worker's
  // credential stands for nobody: one digest and one look-up for check().
  std::optional<Principal> lookup(std::string_view token, std::string* quarantined) const;
  std::map<std::string, Principal> tokens_;  // SHA-256 of the token -> principal
  CredentialBook* book_ = nullptr;
};

const char* role_name(Role role);

}  // namespace tessera
