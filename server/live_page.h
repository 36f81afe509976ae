// The live page the status endpoint serves at / (status_http.h): its markup, style and
// script, served separately so that the Content-Security-Policy can forbid inline script
// (and with it any markup a job or worker name might smuggle in). Every value the script
// writes into the page goes through esc() or textContent. Actions (page_actions.h) send
// the token the page holds (asked for once, kept for the browser tab) as a Bearer header.
#pragma once

namespace tessera {

extern const char* const kLivePage;  // text/html
extern const char* const kLiveCss;   // text/css
extern const char* const kLiveJs;    // text/javascript

}  // namespace tessera
