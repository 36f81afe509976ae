// The live page's actions, over HTTP beside the status endpoint (status_http.h):
//   POST /api/jobs/<id>/cancel | requeue | delete      a client its own jobs, an admin any
//   POST /api/jobs/<id>/priority?value=N                as tessera cancel/requeue/...
//   POST /api/workers/<id>/drain | resume               admins only
// Safe against cross-site requests: every action needs the X-Tessera-Action header (a
// cross-site form cannot send it, and a cross-site script cannot without a CORS preflight
// this server never grants), a cross-site Origin or Sec-Fetch-Site is refused, and with
// access tokens the token must come as "Authorization: Bearer" (the page holds it), never
// as HTTP Basic, which a browser attaches to any request by itself. Answers JSON: the job's
// status, or {"error": "..."} naming what is wrong.
#pragma once

#include <httplib.h>

#include "server/auth.h"
#include "server/coordinator.h"

namespace tessera {

void add_page_actions(httplib::Server& server, Coordinator& c, const Authenticator* auth);

}  // namespace tessera
