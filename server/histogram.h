// Prometheus histograms: counts under fixed upper bounds, written cumulative with their sum
// and count. Histogram is a plain value (the coordinator keeps one under its lock, in its
// counters); RpcLatency is the process's, for every gRPC call, thread-safe.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>

namespace tessera {

struct Histogram {
  // Seconds, from a fast RPC to a long task.
  static constexpr std::array<double, 14> kBounds = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05,
                                                     0.1,    0.25,  0.5,    1,     2.5,  10,    60};
  std::array<uint64_t, kBounds.size() + 1> counts{};  // per bucket; the last is +Inf
  double sum = 0;
  uint64_t count = 0;

  void observe(double seconds);
  // `name`_bucket{labels,le="..."} lines (cumulative), `name`_sum and `name`_count;
  // `labels` is empty or `key="value",...` without braces. No HELP or TYPE lines.
  void write(std::string& out, const std::string& name, const std::string& labels) const;
};

// Every gRPC call's time in the handler, by method (GetTask's includes its long poll).
class RpcLatency {
 public:
  static RpcLatency& process();
  void observe(const char* method, double seconds);
  // The whole metric family, HELP and TYPE included.
  std::string text() const;

 private:
  mutable std::mutex mu_;
  std::map<std::string, Histogram> by_method_;
};

// A number as Prometheus reads it: integers exactly, others in the shortest form that reads
// back to the same double.
std::string metric_number(double v);
std::string metric_number(uint64_t v);
// A label value with \, " and newline escaped.
std::string metric_label(const std::string& v);

}  // namespace tessera
