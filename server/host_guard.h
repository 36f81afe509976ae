// A guard against DNS rebinding for the status endpoint without access tokens.
//
// A page on a site the attacker owns can have its name re-pointed at this machine (or any
// address the browser reaches): its script then talks to our port as "the same origin",
// with the attacker's name in Host and Origin, so the page actions' same-origin checks
// pass and, without tokens, every caller may do everything. Such a request carries a host
// name the attacker controls; so without tokens the status endpoint answers only requests
// whose Host is an IP address (no DNS to rebind), localhost (browsers resolve it and its
// subdomains to loopback themselves) or a name the operator allowed (--http-allowed-host).
// With tokens the attacker's page has no token to send, and every name is answered.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace tessera {

// True if a request with this Host header (name or address, with or without a port) may be
// answered: an IPv4 or bracketed IPv6 literal, localhost or *.localhost, one of `allowed`
// (compared without case or a final dot), or no Host at all (not a browser's request).
bool host_allowed(std::string_view host_header, const std::vector<std::string>& allowed);

}  // namespace tessera
