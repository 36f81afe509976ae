// What `--json` prints: protobuf's JSON (proto_json: every field, the .proto's names) with
// 64-bit integers as JSON numbers. protobuf's mapping writes int64 and uint64 as strings
// (JavaScript's doubles cannot hold them all); a shell script or jq then has to convert
// samples_done. Every 64-bit count here stays far below 2^53.
#pragma once

#include <google/protobuf/message.h>

#include <string>

namespace tessera {

std::string cli_json(const google::protobuf::Message& m);

}  // namespace tessera
