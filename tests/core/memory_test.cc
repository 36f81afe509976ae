// The memory a process may use (core/util/memory.h): the machine's, or a cgroup's limit
// where lower, which the memory-sized defaults follow.
#include "core/util/memory.h"

#include <gtest/gtest.h>

#include <map>
#include <string>

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

// Slurm and systemd set a limit on a group above the process's own (a job above its step's
// task): every group up to the root counts, cgroup v2 and v1 alike.
TEST(MemoryLimit, EveryGroupUpToTheRootCounts) {
  const std::map<std::string, std::string> files = {
      {"/sys/fs/cgroup/slurm/job_7/step_0/task_0/memory.max", "max\n"},
      {"/sys/fs/cgroup/slurm/job_7/step_0/memory.max", "max\n"},
      {"/sys/fs/cgroup/slurm/job_7/memory.max", "6442450944\n"},
      {"/sys/fs/cgroup/memory.max", "max\n"},
      {"/sys/fs/cgroup/memory/system.slice/w.service/memory.limit_in_bytes", "9223372036854771712\n"},
      {"/sys/fs/cgroup/memory/system.slice/memory.limit_in_bytes", "3221225472\n"},
  };
  const auto read = [&](const std::string& path) {
    const auto it = files.find(path);
    return it == files.end() ? std::string() : it->second;
  };
  EXPECT_EQ(cgroup_memory_limit(128 * kGiB, "0::/slurm/job_7/step_0/task_0\n", read), 6 * kGiB);
  EXPECT_EQ(cgroup_memory_limit(128 * kGiB, "5:cpu,cpuacct:/x\n4:memory:/system.slice/w.service\n", read), 3 * kGiB);
  EXPECT_EQ(cgroup_memory_limit(128 * kGiB, "0::/\n", read), 128 * kGiB);  // a container's own namespace: its root
  EXPECT_EQ(cgroup_memory_limit(128 * kGiB, "", read), 128 * kGiB);
  EXPECT_EQ(cgroup_memory_limit(128 * kGiB, "garbage\n3:pids:/a\n", read), 128 * kGiB);
}

}  // namespace
}  // namespace tessera
