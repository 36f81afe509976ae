#include "access.h"

#include <cstdlib>
#include <stdexcept>

#include "core/io/files.h"

namespace tessera {
namespace {

std::string trimmed(std::string s) {
  const size_t a = s.find_first_not_of(" \t\r\n"), b = s.find_last_not_of(" \t\r\n");
  return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

std::string env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

}  // namespace

std::string read_token_file(const std::string& path) {
  std::string token = trimmed(read_file_bytes(path));
  if (token.empty()) throw std::runtime_error(path + ": no token in the file");
  if (token.find_first_of(" \t\r\n") != std::string::npos)
    throw std::runtime_error(path + ": a token file holds one token, on one line");
  return token;
}

Access load_access(const std::string& token_file, const std::string& ca_file) {
  Access a;
  const std::string tf = token_file.empty() ? env("TESSERA_TOKEN_FILE") : token_file;
  if (!tf.empty()) {
    a.token = read_token_file(tf);
  } else {
    a.token = trimmed(env("TESSERA_TOKEN"));
  }
  const std::string cf = ca_file.empty() ? env("TESSERA_TLS_CA") : ca_file;
  if (!cf.empty()) a.tls_ca_pem = read_file_bytes(cf);
  return a;
}

std::shared_ptr<grpc::ChannelCredentials> channel_credentials(const Access& access) {
  if (access.tls_ca_pem.empty()) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = access.tls_ca_pem;
  return grpc::SslCredentials(o);
}

void authorize(grpc::ClientContext& context, const Access& access) {
  if (!access.token.empty()) context.AddMetadata("authorization", "Bearer " + access.token);
}

}  // namespace tessera
