#include "server/histogram.h"

#include <charconv>
#include <cmath>

namespace tessera {

void Histogram::observe(double seconds) {
  if (!(seconds >= 0)) seconds = 0;
  size_t i = 0;
  while (i < kBounds.size() && seconds > kBounds[i]) ++i;
  ++counts[i];
  sum += seconds;
  ++count;
}

namespace {
std::string bound_text(double b) {  // "0.0005", as Prometheus's own clients write bounds
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, b, std::chars_format::fixed);
  return std::string(buf, r.ptr);
}
}  // namespace

void Histogram::write(std::string& out, const std::string& name, const std::string& labels) const {
  const std::string sep = labels.empty() ? "" : ",";
  uint64_t cumulative = 0;
  for (size_t i = 0; i <= kBounds.size(); ++i) {
    cumulative += counts[i];
    out += name + "_bucket{" + labels + sep + "le=\"" + (i < kBounds.size() ? bound_text(kBounds[i]) : "+Inf") +
           "\"} " + metric_number(cumulative) + "\n";
  }
  const std::string braces = labels.empty() ? "" : "{" + labels + "}";
  out += name + "_sum" + braces + " " + metric_number(sum) + "\n";
  out += name + "_count" + braces + " " + metric_number(count) + "\n";
}

RpcLatency& RpcLatency::process() {
  static RpcLatency r;
  return r;
}

void RpcLatency::observe(const char* method, double seconds) {
  std::lock_guard<std::mutex> lock(mu_);
  by_method_[method].observe(seconds);
}

std::string RpcLatency::text() const {
  std::string out =
      "# HELP tessera_rpc_seconds Time in the coordinator's gRPC handlers, by method (GetTask's includes its long "
      "poll).\n# TYPE tessera_rpc_seconds histogram\n";
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& [method, h] : by_method_) h.write(out, "tessera_rpc_seconds", "method=\"" + method + "\"");
  return out;
}

std::string metric_number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

std::string metric_number(uint64_t v) { return std::to_string(v); }

std::string metric_label(const std::string& v) {
  std::string out;
  for (char c : v) {
    if (c == '\\' || c == '"') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out;
}

}  // namespace tessera
