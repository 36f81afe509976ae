#include "core/util/log.h"

#include <spdlog/sinks/stdout_sinks.h>

#include <atomic>

namespace tessera {

void init_logging(const std::string& program, bool verbose) {
  auto logger = spdlog::stderr_logger_mt(program);
  // 2026-11-24T09:15:02.118+0000 tessera-coordinator warning: ...
  logger->set_pattern("%Y-%m-%dT%H:%M:%S.%e%z %n %l: %v");
  logger->set_level(verbose ? spdlog::level::debug : spdlog::level::info);
  logger->flush_on(spdlog::level::trace);  // every line at once: operators tail these
  spdlog::set_default_logger(std::move(logger));
}

std::string log_incident(const std::string& what) {
  static std::atomic<uint64_t> incidents{0};
  const uint64_t n = ++incidents;
  spdlog::error("internal error #{}: {}", n, what);
  return "internal error #" + std::to_string(n) + " (the coordinator's log has its details)";
}

}  // namespace tessera
