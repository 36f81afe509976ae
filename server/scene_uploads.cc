#include "server/scene_uploads.h"

#include <cstdio>
#include <filesystem>
#include <random>
#include <vector>

#include "core/util/text.h"
#include "server/request_error.h"
#include "wire.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

std::string new_upload_id() {  // 128 bits from the system's entropy: the id is the upload's key
  std::random_device rd;
  char buf[33];
  std::snprintf(buf, sizeof buf, "%08x%08x%08x%08x", rd(), rd(), rd(), rd());
  return buf;
}

RequestError refuse(const std::string& why) { return RequestError(RequestError::Code::kInvalidArgument, why); }

RequestError no_upload(const std::string& id, double kept_seconds) {
  return RequestError(RequestError::Code::kNotFound, "no scene upload '" + utf8_prefix(id, 64) +
                                                         "' (an upload is good for one submit, within " +
                                                         std::to_string(int(kept_seconds)) + " s of its end)");
}

}  // namespace

uint64_t SceneUploads::held_locked(const std::string& owner) const {
  uint64_t n = 0;
  for (const auto& [id, u] : uploads_)
    if (u.owner == owner) n += u.bytes;
  return n;
}

uint64_t SceneUploads::held(const std::string& owner) {
  std::lock_guard<std::mutex> lock(mu_);
  return held_locked(owner);
}

void SceneUploads::forget(const std::string& id) {
  std::string folder;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = uploads_.find(id);
    if (it == uploads_.end()) return;
    folder = it->second.folder;
    uploads_.erase(it);
  }
  std::error_code ec;
  fs::remove_all(folder, ec);
}

void SceneUploads::drop_expired() {
  const double now = clock_.now();
  std::vector<std::string> folders;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = uploads_.begin(); it != uploads_.end();)
      if (it->second.expires >= 0 && it->second.expires <= now) {
        folders.push_back(it->second.folder);
        it = uploads_.erase(it);
      } else {
        ++it;
      }
  }
  for (const std::string& f : folders) {
    std::error_code ec;
    fs::remove_all(f, ec);
  }
}

v1::SceneUpload SceneUploads::receive(const std::string& owner, const std::function<bool(v1::SceneChunk*)>& next,
                                      uint64_t owner_bytes, uint64_t limit) {
  drop_expired();
  v1::SceneChunk first;
  if (!next(&first)) throw refuse("scene upload: the stream ended before its manifest");
  if (!first.has_manifest()) throw refuse("scene upload: its first message has no manifest");
  uint64_t bytes = 0;
  try {
    bytes = check_manifest(first.manifest());
  } catch (const WireError& e) {
    throw refuse(e.what());
  }
  const std::string id = new_upload_id(), folder = scenes_.staging_folder("upload");
  {
    std::lock_guard<std::mutex> lock(mu_);
    const uint64_t held = owner_bytes + held_locked(owner);
    if (held + bytes > limit) {
      const std::string who = owner.empty() ? std::string("this coordinator") : "client '" + owner + "'";
      throw RequestError(RequestError::Code::kResourceExhausted,
                         who + "'s live jobs and uploads hold " + std::to_string(held) +
                             " scene bytes; this upload's " + std::to_string(bytes) + " would pass the limit of " +
                             std::to_string(limit) + " (--max-scene-bytes-per-client)");
    }
    uploads_[id] = Upload{owner, folder, first.manifest(), bytes};
  }
  // From here on, a failure takes the upload and its folder away.
  try {
    SceneReceiver rx(folder + "/files", first.manifest());
    v1::SceneChunk piece;
    while (next(&piece)) rx.add(piece);
    rx.finish();
  } catch (const WireError& e) {
    forget(id);
    throw refuse(e.what());
  } catch (const std::exception& e) {  // the disk: full, say
    forget(id);
    const auto* fse = dynamic_cast<const fs::filesystem_error*>(&e);
    throw RequestError(RequestError::Code::kResourceExhausted, std::string("the coordinator cannot keep the scene: ") +
                                                                   (fse ? fse->code().message() : e.what()));
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    uploads_.at(id).expires = clock_.now() + kept_seconds_;
  }
  v1::SceneUpload out;
  out.set_upload_id(id);
  out.set_scene_hash(first.manifest().scene_hash());
  return out;
}

uint64_t SceneUploads::bytes(const std::string& id, const std::string& owner) {
  drop_expired();
  std::lock_guard<std::mutex> lock(mu_);
  const auto it = uploads_.find(id);
  if (it == uploads_.end() || it->second.owner != owner || it->second.expires < 0) throw no_upload(id, kept_seconds_);
  return it->second.bytes;
}

std::string SceneUploads::submit(const std::string& id, const std::string& owner, const SceneStore::Check& check,
                                 std::string* main_file) {
  drop_expired();
  Upload u;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = uploads_.find(id);
    if (it == uploads_.end() || it->second.owner != owner || it->second.expires < 0) throw no_upload(id, kept_seconds_);
    u = std::move(it->second);
    uploads_.erase(it);
  }
  *main_file = u.manifest.main_file();
  return scenes_.keep(u.folder, u.manifest, check);
}

}  // namespace tessera
