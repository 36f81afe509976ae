// What clients see of jobs: a job's or a sequence's status (JobStatus, with the workers
// holding leases on it) and the list of every job in submission order, frames inside their
// sequences. Runs under the coordinator's lock.
#pragma once

#include <string>
#include <vector>

#include "server/job_table.h"
#include "server/lease_table.h"

namespace tessera {

// Throws RequestError (kNotFound) for an unknown id.
v1::JobStatus job_status(const JobTable& jobs, const LeaseTable& leases, const std::string& id, bool with_tiles,
                         double now);
std::vector<v1::JobStatus> job_list(const JobTable& jobs, const LeaseTable& leases, double now);

}  // namespace tessera
