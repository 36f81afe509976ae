// How a client or a worker reaches the coordinator: its access token and, for TLS, the
// certificate authority to trust. Tokens come from a file or the environment, never from
// the command line (where `ps` would show them).
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <string>

namespace tessera {

struct Access {
  std::string token;       // empty: none sent
  std::string tls_ca_pem;  // empty: plaintext
};

// The token from `token_file`, else the file named by $TESSERA_TOKEN_FILE, else
// $TESSERA_TOKEN; the CA certificate from `ca_file`, else the file named by
// $TESSERA_TLS_CA. Throws std::runtime_error naming a file that cannot be read or holds
// no token.
Access load_access(const std::string& token_file = "", const std::string& ca_file = "");
// The one token a file holds (surrounding white space ignored). Throws std::runtime_error
// naming the file.
std::string read_token_file(const std::string& path);

std::shared_ptr<grpc::ChannelCredentials> channel_credentials(const Access& access);
// Adds the token to a call ("authorization: Bearer <token>").
void authorize(grpc::ClientContext& context, const Access& access);

}  // namespace tessera
