#include "client/cli_json.h"

#include <google/protobuf/descriptor.h>

#include <nlohmann/json.hpp>

#include "wire.h"

namespace tessera {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;

nlohmann::json number_of(const nlohmann::json& v, bool is_signed) {
  if (!v.is_string()) return v;
  try {
    const std::string& s = v.get_ref<const std::string&>();
    size_t used = 0;
    nlohmann::json n = is_signed ? nlohmann::json(std::stoll(s, &used)) : nlohmann::json(std::stoull(s, &used));
    return used == s.size() ? n : v;
  } catch (const std::exception&) {  // (not a number after all: left as it is)
    return v;
  }
}

// Turns the 64-bit integer fields of `j` (a message of type `d`) into numbers, through
// nested and repeated messages.
void numbers(const Descriptor* d, nlohmann::json& j) {
  if (!j.is_object()) return;
  for (int i = 0; i < d->field_count(); ++i) {
    const FieldDescriptor* f = d->field(i);
    auto it = j.find(f->name());
    if (it == j.end() || f->is_map()) continue;
    const auto type = f->cpp_type();
    if (type == FieldDescriptor::CPPTYPE_INT64 || type == FieldDescriptor::CPPTYPE_UINT64) {
      const bool is_signed = type == FieldDescriptor::CPPTYPE_INT64;
      if (f->is_repeated() && it->is_array())
        for (auto& e : *it) e = number_of(e, is_signed);
      else
        *it = number_of(*it, is_signed);
    } else if (type == FieldDescriptor::CPPTYPE_MESSAGE) {
      if (f->is_repeated() && it->is_array())
        for (auto& e : *it) numbers(f->message_type(), e);
      else
        numbers(f->message_type(), *it);
    }
  }
}

}  // namespace

std::string cli_json(const google::protobuf::Message& m) {
  nlohmann::json j = nlohmann::json::parse(proto_json(m), nullptr, false);
  if (j.is_discarded()) return proto_json(m);
  numbers(m.GetDescriptor(), j);
  return j.dump();
}

}  // namespace tessera
