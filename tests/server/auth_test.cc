// Access tokens: the token file's hostile or sloppy lines are refused naming the line; a
// header or metadata value maps to one outcome; a client's token file is checked too.
#include "server/auth.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "access.h"
#include "core/io/files.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

std::string refusal(const std::string& text) {
  try {
    Authenticator::from_text(text, "tokens");
  } catch (const AuthConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Auth, TokenFilesThatCannotBeTrustedAreRefusedNamingTheLine) {
  EXPECT_EQ(refusal("# nothing\n\n"), "tokens: no tokens");
  EXPECT_EQ(refusal("client alice\n"), "tokens:1: expected ROLE NAME TOKEN");
  EXPECT_EQ(refusal("client alice 0123456789abcdef extra\n"), "tokens:1: expected ROLE NAME TOKEN");
  EXPECT_EQ(refusal("\nroot alice 0123456789abcdef\n"),
            "tokens:2: unknown role 'root' (viewer, client, worker, enrol or admin)");
  EXPECT_EQ(refusal("client alice short\n"), "tokens:1: token shorter than 16 characters");
  EXPECT_EQ(refusal("client a 0123456789abcdef\nadmin b 0123456789abcdef\n"), "tokens:2: the same token appears twice");
  EXPECT_NE(refusal("").find("no tokens"), std::string::npos);
  try {
    Authenticator::from_file("/nonexistent/tokens");
    ADD_FAILURE();
  } catch (const AuthConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/tokens"), std::string::npos) << e.what();
  }
}

TEST(Auth, EveryHeaderGivesOneOutcome) {
  const Authenticator a =
      Authenticator::from_text("viewer ops viewer-0123456789ab # a comment\nworker farm worker-0123456789ab\n", "t");
  using C = Authenticator::Check;
  EXPECT_EQ(a.check("", Action::kRead).outcome, C::kUnauthenticated);
  EXPECT_NE(a.check("", Action::kRead).why.find("needs an access token"), std::string::npos);
  EXPECT_EQ(a.check("Bearer nope-0123456789abcdef", Action::kRead).outcome, C::kUnauthenticated);
  EXPECT_EQ(a.check("Token viewer-0123456789ab", Action::kRead).outcome, C::kUnauthenticated);  // unknown scheme
  const C ok = a.check("Bearer viewer-0123456789ab", Action::kRead);
  EXPECT_EQ(ok.outcome, C::kAllowed);
  EXPECT_EQ(ok.who.name, "ops");
  const C denied = a.check("Bearer worker-0123456789ab", Action::kRead);
  EXPECT_EQ(denied.outcome, C::kDenied);
  EXPECT_EQ(denied.why, "a worker token may not do this");
  // HTTP Basic: the token is the password; malformed base64 is no token at all.
  EXPECT_EQ(a.check("Basic b3BzOnZpZXdlci0wMTIzNDU2Nzg5YWI=", Action::kRead).outcome, C::kAllowed);  // ops:viewer-...
  EXPECT_EQ(a.check("Basic b3BzOnZpZXdlci0wMTIzNDU2Nzg5YWI", Action::kRead).outcome, C::kUnauthenticated);
  EXPECT_EQ(a.check("Basic !!!!", Action::kRead).outcome, C::kUnauthenticated);
  EXPECT_EQ(a.check("Basic " + std::string(10000, 'A'), Action::kRead).outcome, C::kUnauthenticated);
  // Without tokens everyone is an admin.
  EXPECT_EQ(Authenticator().check("", Action::kWork).outcome, C::kAllowed);
}

TEST(Auth, AClientTokenFileHoldsOneToken) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_auth_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string empty = (dir / "empty").string(), two = (dir / "two").string(), one = (dir / "one").string();
  write_file_atomic(empty, "\n");
  write_file_atomic(two, "abc def\n");
  write_file_atomic(one, "  the-token \n");
  EXPECT_THROW(load_access(empty), std::runtime_error);
  try {
    load_access(two);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("one token, on one line"), std::string::npos) << e.what();
  }
  EXPECT_EQ(load_access(one).token, "the-token");
  EXPECT_THROW(load_access((dir / "missing").string()), std::runtime_error);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
