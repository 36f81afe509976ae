// /api/jobs/<id>'s JSON: the tiles written by hand read back as protobuf's own printer
// writes them (which cost 6.5 s and 0.9 GB for an 8K frame's 262,144 tiles).
#include "server/status_http.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <thread>

#include "server/http_listener.h"
#include "wire.h"

namespace tessera {
namespace {

TEST(StatusHttp, AJobsTilesReadBackAsProtobufPrintsThem) {
  v1::JobStatus s;
  s.set_id("abc");
  s.set_state(v1::JobStatus::RUNNING);
  s.set_tiles_total(4);
  const float errors[] = {0.1f, 1.0f / 3, std::numeric_limits<float>::infinity(), 0};
  for (int i = 0; i < 4; ++i) {
    v1::TileProgress* t = s.add_tiles();
    t->mutable_rect()->set_x(uint32_t(16 * i));
    t->mutable_rect()->set_w(16);
    t->mutable_rect()->set_h(i == 3 ? 5 : 16);
    t->set_passes_done(uint32_t(i));
    t->set_samples(uint32_t(64 * i));
    t->set_relative_error(errors[i]);
    t->set_finished(i == 3);
  }
  const nlohmann::json ours = nlohmann::json::parse(job_status_json(s));
  const nlohmann::json theirs = nlohmann::json::parse(proto_json(s));
  ASSERT_EQ(ours["tiles"].size(), 4u);
  for (int i = 0; i < 4; ++i) {
    nlohmann::json a = ours["tiles"][size_t(i)], b = theirs["tiles"][size_t(i)];
    if (a["relative_error"].is_number()) {  // the same float, however it is spelled
      EXPECT_EQ(float(a["relative_error"].get<double>()), float(b["relative_error"].get<double>())) << i;
      a.erase("relative_error");
      b.erase("relative_error");
    }
    EXPECT_EQ(a, b) << i;
  }
  nlohmann::json rest = ours, their_rest = theirs;
  rest.erase("tiles");
  their_rest.erase("tiles");
  rest.erase("tiles_from");
  rest.erase("tiles_next");
  EXPECT_EQ(rest, their_rest);
  // No tiles: an empty list, as protobuf prints it.
  EXPECT_EQ(nlohmann::json::parse(job_status_json(v1::JobStatus()))["tiles"], nlohmann::json::array());
  // A page: where it starts, and where the next does (none after the last).
  EXPECT_EQ(ours["tiles_from"], 0);
  EXPECT_EQ(ours["tiles_next"], nullptr);
  s.set_tiles_total(10);
  const nlohmann::json page = nlohmann::json::parse(job_status_json(s, 3));
  EXPECT_EQ(page["tiles_from"], 3);
  EXPECT_EQ(page["tiles_next"], 7);
}

// Found by review: a handler's unexpected exception reached cpp-httplib's own answer, which
// put its text in an EXCEPTION_WHAT header (a preview's named the image's path on the
// coordinator's disk). The log has it; the caller gets a number, as on the gRPC side.
TEST(HttpListener, AnUnexpectedExceptionIsAnsweredWithAnIncidentNumberOnly) {
  HttpListener http(std::make_unique<httplib::Server>(), "http");
  http.server().Get("/boom", [](const httplib::Request&, httplib::Response&) {
    throw std::runtime_error("/var/lib/tessera/jobs/abc/image.exr: cannot read");
  });
  const int port = http.bind("127.0.0.1", 0);
  http.start();
  httplib::Client client("127.0.0.1", port);
  httplib::Result r = client.Get("/boom");
  for (int i = 0; !r && i < 50; ++i) {  // (the listener's thread may not serve yet)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    r = client.Get("/boom");
  }
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 500);
  EXPECT_FALSE(r->has_header("EXCEPTION_WHAT"));
  EXPECT_EQ(r->body.rfind("internal error #", 0), 0u) << r->body;
  EXPECT_EQ(r->body.find("/var/lib"), std::string::npos) << r->body;
  http.stop();
}

// Found by audit: a request's body was read whole before its handler (cpp-httplib's
// default bound is none), so one caller's POST could take all the coordinator's memory.
// Past kMaxBodyBytes it is answered 413 without being read.
TEST(HttpListener, ARequestsBodyIsBounded) {
  HttpListener http(std::make_unique<httplib::Server>(), "http");
  http.server().Post("/echo", [](const httplib::Request& req, httplib::Response& res) {
    res.set_content(std::to_string(req.body.size()), "text/plain");
  });
  const int port = http.bind("127.0.0.1", 0);
  http.start();
  httplib::Client client("127.0.0.1", port);
  httplib::Result r = client.Post("/echo", "x", "text/plain");
  for (int i = 0; !r && i < 50; ++i) {  // (the listener's thread may not serve yet)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    r = client.Post("/echo", "x", "text/plain");
  }
  ASSERT_TRUE(r);
  EXPECT_EQ(r->body, "1");
  r = client.Post("/echo", std::string(HttpListener::kMaxBodyBytes, 'x'), "text/plain");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->body, std::to_string(HttpListener::kMaxBodyBytes));
  r = client.Post("/echo", std::string(HttpListener::kMaxBodyBytes + 1, 'x'), "text/plain");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 413);
  http.stop();
}

}  // namespace
}  // namespace tessera
