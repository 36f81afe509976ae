#include "server/page_actions.h"

#include <charconv>
#include <nlohmann/json.hpp>
#include <optional>

#include "server/json_text.h"
#include "server/request_error.h"

namespace tessera {
namespace {

void error(httplib::Response& res, int status, const std::string& why) {
  res.status = status;
  res.set_content(lenient_dump({{"error", why}}), "application/json");
}

// Who asks, if the request may act at all (else the answer is written): the caller's
// token name and whether it may act on anyone's jobs.
struct Actor {
  std::string name;
  bool any = true;
  bool admin = true;
};
std::optional<Actor> actor(const httplib::Request& req, httplib::Response& res, const Authenticator* auth) {
  if (!req.has_header("X-Tessera-Action")) {
    error(res, 403,
          "an action needs the X-Tessera-Action header (the live page's script sends it; a cross-site form cannot)");
    return std::nullopt;
  }
  const std::string origin = req.get_header_value("Origin"), host = req.get_header_value("Host");
  if (!origin.empty() && origin != "http://" + host && origin != "https://" + host) {
    error(res, 403, "cross-site request refused: Origin " + origin + " is not this server's");
    return std::nullopt;
  }
  const std::string site = req.get_header_value("Sec-Fetch-Site");
  if (!site.empty() && site != "same-origin" && site != "none") {
    error(res, 403, "cross-site request refused (Sec-Fetch-Site: " + site + ")");
    return std::nullopt;
  }
  if (!auth || !auth->enabled()) return Actor{};
  const std::string authorization = req.get_header_value("Authorization");
  if (authorization.rfind("Bearer ", 0) != 0) {
    error(res, 401,
          "an action needs its token as \"Authorization: Bearer TOKEN\" (the page asks for it), not HTTP Basic, which "
          "a browser sends by itself");
    return std::nullopt;
  }
  const Authenticator::Check c = auth->check(authorization, Action::kCancel);
  if (c.outcome != Authenticator::Check::kAllowed) {
    error(res, c.outcome == Authenticator::Check::kUnauthenticated ? 401 : 403, c.why);
    return std::nullopt;
  }
  const bool admin = c.who.role == Role::kAdmin;
  return Actor{c.who.name, admin, admin};
}

int http_status(RequestError::Code code) {
  switch (code) {
    case RequestError::Code::kInvalidArgument:
      return 400;
    case RequestError::Code::kNotFound:
      return 404;
    case RequestError::Code::kFailedPrecondition:
      return 409;
    case RequestError::Code::kResourceExhausted:
      return 429;
    case RequestError::Code::kPermissionDenied:
      return 403;
  }
  return 500;
}

// Runs the action, answering its JSON or the error that names what is wrong.
template <typename Act>
void answer(httplib::Response& res, Act&& act) {
  try {
    res.set_content(act(), "application/json");
  } catch (const RequestError& e) {
    error(res, http_status(e.code()), e.what());
  }
}

}  // namespace

void add_page_actions(httplib::Server& server, Coordinator& c, const Authenticator* auth) {
  server.Post(R"(/api/jobs/([A-Za-z0-9-]+)/(cancel|requeue|delete|priority))",
              [&c, auth](const httplib::Request& req, httplib::Response& res) {
                const std::optional<Actor> who = actor(req, res, auth);
                if (!who) return;
                const std::string id = req.matches[1], what = req.matches[2];
                int32_t priority = 0;
                if (what == "priority") {
                  const std::string v = req.get_param_value("value");
                  const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), priority);
                  if (v.empty() || ec != std::errc() || end != v.data() + v.size())
                    return error(res, 400, "priority: value '" + v + "' is not a whole number");
                }
                answer(res, [&] {
                  if (what == "cancel") return proto_json(c.cancel(id, who->name, who->any));
                  if (what == "requeue") return proto_json(c.requeue(id, who->name, who->any));
                  if (what == "priority") return proto_json(c.set_priority(id, priority, who->name, who->any));
                  const uint64_t freed = c.remove(id, who->name, who->any);
                  return nlohmann::json{{"id", id}, {"bytes_freed", freed}}.dump();
                });
              });
  server.Post(R"(/api/workers/(\d+)/(drain|resume))", [&c, auth](const httplib::Request& req, httplib::Response& res) {
    const std::optional<Actor> who = actor(req, res, auth);
    if (!who) return;
    if (!who->admin) return error(res, 403, "only an admin may drain or resume a worker");
    uint64_t id = 0;
    const std::string v = req.matches[1];
    if (std::from_chars(v.data(), v.data() + v.size(), id).ec != std::errc())
      return error(res, 400, "worker id " + v.substr(0, 32) + " is not a worker id (past 2^64)");
    const bool drain = req.matches[2] == "drain";
    answer(res, [&] {
      c.drain_worker(id, drain, who->name);
      return nlohmann::json{{"id", id}, {"draining", drain}}.dump();
    });
  });
}

}  // namespace tessera
