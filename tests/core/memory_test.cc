// The memory a process may use (core/util/memory.h): the machine's, or a cgroup's limit
// where lower, which the memory-sized defaults follow.
#include "core/util/memory.h"

#include <gtest/gtest.h>

namespace tessera {
namespace {

constexpr uint64_t kGiB = uint64_t(1) << 30;

TEST(MemoryLimit, ACgroupLimitBelowTheMachineIsWhatCounts) {
  EXPECT_EQ(memory_limit_from(128 * kGiB, "8589934592\n", ""), 8 * kGiB);  // a pod's memory.max (v2)
  EXPECT_EQ(memory_limit_from(128 * kGiB, "", "4294967296\n"), 4 * kGiB);  // cgroup v1
  EXPECT_EQ(memory_limit_from(128 * kGiB, "8589934592", "4294967296"), 4 * kGiB);
}

TEST(MemoryLimit, NoLimitOrAnUnreadableOneIsTheMachines) {
  EXPECT_EQ(memory_limit_from(24 * kGiB, "max\n", ""), 24 * kGiB);
  EXPECT_EQ(memory_limit_from(24 * kGiB, "", "9223372036854771712\n"), 24 * kGiB);  // v1's "unlimited"
  EXPECT_EQ(memory_limit_from(24 * kGiB, "", ""), 24 * kGiB);
  EXPECT_EQ(memory_limit_from(24 * kGiB, "-1", "12abc"), 24 * kGiB);
  EXPECT_EQ(memory_limit_from(24 * kGiB, "0", "99999999999999999999999"), 24 * kGiB);
  EXPECT_GT(usable_memory_bytes(), 0u);
}

}  // namespace
}  // namespace tessera
