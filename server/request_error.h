// A request the coordinator refuses, with a message for the client and the kind of refusal
// (grpc_services.cc maps it to a gRPC status code).
#pragma once

#include <stdexcept>
#include <string>

namespace tessera {

class RequestError : public std::runtime_error {
 public:
  enum class Code { kInvalidArgument, kNotFound, kFailedPrecondition, kResourceExhausted, kPermissionDenied };
  RequestError(Code code, const std::string& what) : std::runtime_error(what), code_(code) {}
  Code code() const { return code_; }

 private:
  Code code_;
};

}  // namespace tessera
