// How much memory this process may use: the machine's, or less where a cgroup limits it (a
// container's memory limit, a Slurm job's, a systemd unit's MemoryMax). Defaults sized by
// memory (the coordinator's live pixels and scene loads, a worker's kept renderers) use
// this, so that a worker in a 8 GiB pod on a 128 GiB node sizes itself by 8 GiB.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace tessera {

// `physical` bytes, or a cgroup's limit where lower: `v2` is a cgroup v2 memory.max
// ("max" or a number), `v1` a cgroup v1 memory.limit_in_bytes (a number; an unlimited v1
// group says a huge one); empty or unreadable texts limit nothing.
uint64_t memory_limit_from(uint64_t physical, const std::string& v2, const std::string& v1);

// `physical`, or the lowest memory limit of the groups `own_groups` (/proc/self/cgroup's
// text) names and their ancestors (Slurm and systemd set limits above the process's own
// group), v2 (memory.max) and v1 (memory.limit_in_bytes), each file's text by `read`.
uint64_t cgroup_memory_limit(uint64_t physical, const std::string& own_groups,
                             const std::function<std::string(const std::string&)>& read);

// cgroup_memory_limit with this machine's physical memory and this process's groups.
uint64_t usable_memory_bytes();

}  // namespace tessera
