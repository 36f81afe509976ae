// /metrics: the coordinator in Prometheus's text format. Counters are exact integers;
// workers are labelled by name (stable across their restarts, where ids are not); the
// build is tessera_build_info; task and RPC times are histograms. docs/deploy.md lists
// the metrics an operator watches.
#pragma once

#include <string>

#include "server/coordinator.h"

namespace tessera {

std::string prometheus_text(const Coordinator& c);

}  // namespace tessera
