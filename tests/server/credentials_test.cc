// Workers' own credentials (server/credentials.h, issue 23): enrolment, the names it takes,
// its bound per enrolment token, a quarantine that holds across a restart, expiry; and the
// Authenticator's use of them (the enrol role enrols and does nothing else).
#include "server/credentials.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "server/auth.h"
#include "server/request_error.h"
#include "server/secrets.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using Code = RequestError::Code;
using testing::refusal;

struct Wall {
  double t = 1e9;
};

std::unique_ptr<MemoryJobStore> store_at(Wall& wall) {
  auto s = std::make_unique<MemoryJobStore>();
  s->wall = [&wall] { return wall.t; };
  return s;
}

TEST(Credentials, EachEnrolmentIsAWorkerOfItsOwnAndANameEnrolledAgainReplacesItsCredential) {
  Wall wall;
  auto store = store_at(wall);
  CredentialBook book(*store);
  const std::string a = book.enrol("node-1:42", "farm", 10);
  const std::string b = book.enrol("node-2", "farm", 10);
  EXPECT_EQ(a.size(), 48u);  // 192 bits, hex
  EXPECT_NE(a, b);
  ASSERT_TRUE(book.find(sha256(a)));
  EXPECT_EQ(book.find(sha256(a))->name, "node-1:42");
  EXPECT_FALSE(book.find(sha256(a))->quarantined);
  EXPECT_FALSE(book.find(sha256("not-a-credential")));
  // Only the digest is kept.
  for (const StoredCredential& c : store->credentials()) EXPECT_EQ(c.digest.size(), 32u);
  // A restarted worker enrols its name again: the old credential stops working.
  const std::string a2 = book.enrol("node-1:42", "farm", 10);
  EXPECT_FALSE(book.find(sha256(a)));
  EXPECT_TRUE(book.find(sha256(a2)));
  EXPECT_EQ(book.size(), 2u);
  // Names are bounded and plain.
  for (const std::string& bad : std::vector<std::string>{"", std::string(129, 'x'), "a b", "a/b", "<script>", "x\n"})
    EXPECT_NE(refusal([&] { book.enrol(bad, "farm", 10); }, Code::kInvalidArgument).find("worker name"),
              std::string::npos);
}

TEST(Credentials, EnrolmentsAreBoundedPerEnrolmentTokenNamingTheFlag) {
  Wall wall;
  auto store = store_at(wall);
  CredentialBook book(*store);
  book.enrol("a", "farm", 2);
  book.enrol("b", "farm", 2);
  EXPECT_NO_THROW(book.enrol("a", "farm", 2));  // the same worker again: no more room needed
  const std::string why = refusal([&] { book.enrol("c", "farm", 2); }, Code::kResourceExhausted);
  EXPECT_NE(why.find("enrolment token 'farm' has its 2 workers (--max-workers-per-token"), std::string::npos) << why;
  EXPECT_NO_THROW(book.enrol("c", "lab", 2));  // another enrolment token's workers are not locked out
  // ... nor can it take over their names.
  EXPECT_NE(refusal([&] { book.enrol("a", "lab", 2); }, Code::kPermissionDenied).find("another enrolment token"),
            std::string::npos);
  // Credentials unused for an hour are forgotten, and make room.
  wall.t += CredentialBook::kIdleSeconds + 1;
  EXPECT_NO_THROW(book.enrol("c", "farm", 2));
  EXPECT_EQ(book.size(), 1u);  // a, b and lab's c went; farm's c is new
}

TEST(Credentials, AQuarantineRefusesTheCredentialAndTheNameAndSurvivesARestart) {
  Wall wall;
  auto store = store_at(wall);
  std::string liar, honest;
  {
    CredentialBook book(*store);
    liar = book.enrol("liar", "farm", 10);
    honest = book.enrol("honest", "farm", 10);
    book.quarantine("liar", "job 1 tile 3 pass 0: its sums differ from the coordinator's render");
  }
  CredentialBook book(*store);  // a restarted coordinator
  ASSERT_TRUE(book.find(sha256(liar)));
  EXPECT_TRUE(book.find(sha256(liar))->quarantined);
  EXPECT_FALSE(book.find(sha256(honest))->quarantined);
  const std::string why = refusal([&] { book.enrol("liar", "farm", 10); }, Code::kPermissionDenied);
  EXPECT_NE(why.find("worker 'liar' is quarantined (job 1 tile 3"), std::string::npos) << why;
  // Used or not, a quarantine lasts kQuarantineSeconds; then the name may enrol again.
  wall.t += CredentialBook::kIdleSeconds + 1;
  EXPECT_TRUE(book.find(sha256(honest)));  // (and the honest worker's is in use)
  book.expire();
  EXPECT_TRUE(book.find(sha256(liar)));
  wall.t += CredentialBook::kQuarantineSeconds;
  book.find(sha256(honest));
  book.expire();
  EXPECT_FALSE(book.find(sha256(liar)));
  EXPECT_NO_THROW(book.enrol("liar", "farm", 10));
}

TEST(Credentials, TheSqliteStoreKeepsThem) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_credentials_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  std::string c;
  {
    SqliteJobStore store(dir.string());
    CredentialBook book(store);
    c = book.enrol("node-1", "farm", 10);
    book.enrol("node-2", "farm", 10);
    book.quarantine("node-2", "a test");
  }
  {
    SqliteJobStore store(dir.string());
    CredentialBook book(store);
    EXPECT_EQ(book.size(), 2u);
    ASSERT_TRUE(book.find(sha256(c)));
    EXPECT_FALSE(book.find(sha256(c))->quarantined);
    const std::vector<StoredCredential> all = book.list();
    ASSERT_EQ(all.size(), 2u);
    EXPECT_EQ(all[1].name, "node-2");
    EXPECT_GT(all[1].quarantined_at, 0);
    EXPECT_EQ(all[1].why, "a test");
    EXPECT_EQ(all[1].enroller, "farm");
  }
  fs::remove_all(dir);
}

TEST(Credentials, TheEnrolRoleOnlyEnrolsAndACredentialActsAsItsWorkerOnly) {
  Wall wall;
  auto store = store_at(wall);
  CredentialBook book(*store);
  Authenticator a = Authenticator::from_text("enrol farm enrol-0123456789ab\nclient alice client-0123456789\n", "t");
  a.use_credentials(&book);
  using C = Authenticator::Check;
  EXPECT_EQ(a.check("Bearer enrol-0123456789ab", Action::kEnrol).outcome, C::kAllowed);
  for (Action act : {Action::kRead, Action::kSubmit, Action::kCancel, Action::kWork})
    EXPECT_EQ(a.check("Bearer enrol-0123456789ab", act).outcome, C::kDenied);
  EXPECT_EQ(a.check("Bearer client-0123456789", Action::kEnrol).outcome, C::kDenied);
  const std::string cred = book.enrol("node-1", "farm", 10);
  const C w = a.check("Bearer " + cred, Action::kWork);
  ASSERT_EQ(w.outcome, C::kAllowed);
  EXPECT_EQ(w.who.name, "node-1");
  EXPECT_EQ(w.who.role, Role::kWorker);
  EXPECT_TRUE(w.who.enrolled);
  EXPECT_EQ(a.check("Bearer " + cred, Action::kRead).outcome, C::kDenied);
  EXPECT_EQ(a.check("Bearer " + cred, Action::kEnrol).outcome, C::kDenied);  // a worker does not enrol others
  book.quarantine("node-1", "its sums differ");
  const C q = a.check("Bearer " + cred, Action::kWork);
  EXPECT_EQ(q.outcome, C::kDenied);
  EXPECT_EQ(q.why, "worker 'node-1' is quarantined: its sums differ");
}

}  // namespace
}  // namespace tessera
