// Prometheus text pieces (issue 24): numbers exact (227,850,240 printed as 2.2785e+08 was
// the complaint), labels escaped, histograms cumulative with their sum and count.
#include <gtest/gtest.h>

#include "server/histogram.h"

namespace tessera {
namespace {

TEST(Metrics, NumbersAreExactAndLabelsEscaped) {
  EXPECT_EQ(metric_number(227850240.0), "227850240");
  EXPECT_EQ(metric_number(uint64_t(1) << 60), "1152921504606846976");
  EXPECT_EQ(metric_number(0.1), "0.1");
  EXPECT_EQ(std::stod(metric_number(1.0 / 3)), 1.0 / 3);  // reads back to the same double
  EXPECT_EQ(metric_number(1e30), "1e+30");
  EXPECT_EQ(metric_number(std::numeric_limits<double>::infinity()), "+Inf");
  EXPECT_EQ(metric_label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
}

TEST(Metrics, AHistogramIsWrittenCumulativeWithItsSumAndCount) {
  Histogram h;
  h.observe(0.0001);
  h.observe(0.003);
  h.observe(0.003);
  h.observe(1000);
  std::string out;
  h.write(out, "t", "m=\"x\"");
  EXPECT_NE(out.find("t_bucket{m=\"x\",le=\"0.0005\"} 1\n"), std::string::npos) << out;
  EXPECT_NE(out.find("t_bucket{m=\"x\",le=\"0.005\"} 3\n"), std::string::npos) << out;
  EXPECT_NE(out.find("t_bucket{m=\"x\",le=\"60\"} 3\n"), std::string::npos) << out;
  EXPECT_NE(out.find("t_bucket{m=\"x\",le=\"+Inf\"} 4\n"), std::string::npos) << out;
  EXPECT_NE(out.find("t_sum{m=\"x\"} 1000.0061\n"), std::string::npos) << out;
  EXPECT_NE(out.find("t_count{m=\"x\"} 4\n"), std::string::npos) << out;
}

}  // namespace
}  // namespace tessera
