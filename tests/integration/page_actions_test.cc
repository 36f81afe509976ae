// The live page's actions (server/page_actions.h) through a real coordinator with tokens:
// each allowed only to the roles that may, refused when a browser could have been made to
// send it from another site, with errors that name the problem; and recorded as events
// with who did them.
#include <nlohmann/json.hpp>
#include <thread>

#include "tests/integration/access_fixture.h"

namespace tessera {
namespace {

class PageActions : public Access {
 protected:
  httplib::Result post(const std::string& path, const httplib::Headers& headers) {
    httplib::Client cli("127.0.0.1", http_port);
    return cli.Post(path.c_str(), headers, "", "application/json");
  }
  // As the page sends them: the action header and the token as Bearer.
  httplib::Result act(const std::string& path, const char* token) {
    return post(path, {{"X-Tessera-Action", "1"}, {"Authorization", std::string("Bearer ") + token}});
  }
  nlohmann::json get(const std::string& path) {
    httplib::Client cli("127.0.0.1", http_port);
    auto r = cli.Get(path.c_str(), {{"Authorization", std::string("Bearer ") + kViewer}});
    if (r && r->status != 200 && r->status != 404) ADD_FAILURE() << path << ": " << r->status << " " << r->body;
    return r && r->status == 200 ? nlohmann::json::parse(r->body) : nlohmann::json();
  }
};

TEST_F(PageActions, EachActionIsAllowedOnlyToWhoMayAndNeverFromAnotherSite) {
  start_coordinator();
  const std::string id = submit(kAlice);  // no worker: it stays QUEUED
  const std::string cancel = "/api/jobs/" + id + "/cancel";
  // What a cross-site form or script could send is refused, saying why.
  auto r = post(cancel, {{"Authorization", std::string("Bearer ") + kAlice}});
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403);
  EXPECT_NE(r->body.find("X-Tessera-Action"), std::string::npos) << r->body;
  r = post(cancel, {{"X-Tessera-Action", "1"},
                    {"Authorization", std::string("Bearer ") + kAlice},
                    {"Origin", "http://evil.example"}});
  EXPECT_EQ(r->status, 403);
  EXPECT_NE(r->body.find("cross-site request refused"), std::string::npos) << r->body;
  r = post(cancel, {{"X-Tessera-Action", "1"},
                    {"Authorization", std::string("Bearer ") + kAlice},
                    {"Sec-Fetch-Site", "cross-site"}});
  EXPECT_EQ(r->status, 403);
  // HTTP Basic is what a browser attaches by itself: not for actions.
  r = post(cancel, {{"X-Tessera-Action", "1"}, httplib::make_basic_authentication_header("", kAlice)});
  EXPECT_EQ(r->status, 401);
  EXPECT_NE(r->body.find("Bearer"), std::string::npos) << r->body;
  // Roles: a viewer may not act, nor another client on alice's job.
  EXPECT_EQ(act(cancel, kViewer)->status, 403);
  r = act(cancel, kBob);
  EXPECT_EQ(r->status, 403);
  EXPECT_EQ(get("/api/jobs/" + id)["state"], "QUEUED");
  // Alice may: cancel, a priority (a bad one named), requeue.
  r = act(cancel, kAlice);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(nlohmann::json::parse(r->body)["state"], "CANCELLED");
  r = act("/api/jobs/" + id + "/priority?value=high", kAlice);
  EXPECT_EQ(r->status, 400);
  EXPECT_NE(r->body.find("'high' is not a whole number"), std::string::npos) << r->body;
  r = act("/api/jobs/" + id + "/priority?value=7", kAlice);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(nlohmann::json::parse(r->body)["priority"], 7);
  EXPECT_EQ(act("/api/jobs/" + id + "/requeue", kAlice)->status, 200);
  EXPECT_EQ(act("/api/jobs/no-such-job/cancel", kAlice)->status, 404);

  // Workers: drain and resume, admins only.
  start_worker(kWorker);
  nlohmann::json st;
  for (int i = 0; i < 100 && (st = get("/api/status"))["workers"].empty(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_EQ(st["workers"].size(), 1u);
  const std::string worker = std::to_string(st["workers"][0]["id"].get<uint64_t>());
  r = act("/api/workers/" + worker + "/drain", kAlice);
  EXPECT_EQ(r->status, 403);
  EXPECT_NE(r->body.find("only an admin"), std::string::npos) << r->body;
  ASSERT_EQ(act("/api/workers/" + worker + "/drain", kAdmin)->status, 200);
  EXPECT_EQ(get("/api/status")["workers"][0]["draining"], true);
  ASSERT_EQ(act("/api/workers/" + worker + "/resume", kAdmin)->status, 200);
  EXPECT_EQ(get("/api/status")["workers"][0]["draining"], false);
  EXPECT_EQ(act("/api/workers/12345/drain", kAdmin)->status, 404);
  r = act("/api/workers/99999999999999999999999/drain", kAdmin);  // (was "no worker 0")
  EXPECT_EQ(r->status, 400);
  EXPECT_NE(r->body.find("is not a worker id"), std::string::npos) << r->body;

  // An admin may delete anyone's job.
  r = act("/api/jobs/" + id + "/delete", kAdmin);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_TRUE(get("/api/jobs/" + id).is_null());

  // Every action is an event, with who did it.
  std::map<std::string, std::string> who;  // the first of each kind
  const nlohmann::json events = get("/api/events?limit=100");
  for (const auto& e : events["events"]) who.emplace(e["kind"], e["who"]);
  ASSERT_FALSE(events.is_null());
  EXPECT_EQ(who["job.cancelled"], "alice");
  EXPECT_EQ(who["job.priority"], "alice");
  EXPECT_EQ(who["job.requeued"], "alice");
  EXPECT_EQ(who["worker.drained"], "root");
  EXPECT_EQ(who["worker.resumed"], "root");
  EXPECT_EQ(who["job.deleted"], "root");
}

}  // namespace
}  // namespace tessera
