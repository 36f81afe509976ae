#include "core/scene/gltf/gltf_document.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

#include "core/scene/gltf/gltf_extensions.h"
#include "core/scene/gltf/gltf_prechecks.h"
#include "core/scene/gltf/gltf_textures.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

constexpr uint32_t kGlbJsonChunk = 0x4E4F534Au;  // "JSON"

std::string read_file(const std::string& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) throw SceneError(path, "", "cannot open file");
  if (size > kMaxGltfBufferBytes) throw SceneError(path, "", "file larger than the 1 GiB limit");
  std::ifstream in(path, std::ios::binary);
  std::string s(size, '\0');
  in.read(s.data(), std::streamsize(size));
  if (!in) throw SceneError(path, "", "cannot read file");
  return s;
}

// tinygltf's and nlohmann's messages span lines: join them into one.
std::string first_line(const std::string& s) {
  std::string t;
  for (char c : s) {
    if (c == '\r') continue;
    if (c == '\n') {
      while (!t.empty() && t.back() == ' ') t.pop_back();
      if (!t.empty() && t.back() != ':' && t.back() != ';') t += ';';
      t += ' ';
    } else {
      t += c;
    }
  }
  while (!t.empty() && (t.back() == ' ' || t.back() == ';')) t.pop_back();
  return t;
}

// ---- GLB container -------------------------------------------------------------------
// A little-endian 32-bit word of a GLB at byte `at` (the caller checks the size).
uint32_t glb_u32(const std::string& b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

std::string glb_json(const std::string& b, const std::string& path) {
  auto u32 = [&](size_t at) { return glb_u32(b, at); };
  if (b.size() < 20) throw SceneError(path, "GLB header", "file too short");
  if (u32(4) != 2) throw SceneError(path, "GLB header", "version " + std::to_string(u32(4)) + " (expected 2)");
  if (u32(8) > b.size())
    throw SceneError(path, "GLB header",
                     "declares " + std::to_string(u32(8)) + " bytes, file has " + std::to_string(b.size()));
  const uint32_t json_len = u32(12);
  if (u32(16) != kGlbJsonChunk) throw SceneError(path, "GLB chunk 0", "is not JSON");
  if (uint64_t(json_len) + 20 > b.size())
    throw SceneError(path, "GLB chunk 0", "length " + std::to_string(json_len) + " runs past the end of the file");
  return b.substr(20, json_len);
}

// A GLB with its JSON chunk replaced (padded with spaces to 4 bytes, as the spec asks).
std::string replace_glb_json(const std::string& b, std::string json) {
  const size_t old_end = 20 + size_t(glb_u32(b, 12));
  while (json.size() % 4) json += ' ';
  std::string out = b.substr(0, 12);
  const uint32_t len = uint32_t(json.size()), type = kGlbJsonChunk;
  out.append(reinterpret_cast<const char*>(&len), 4);
  out.append(reinterpret_cast<const char*>(&type), 4);
  out += json;
  out += b.substr(std::min(old_end, b.size()));
  const uint32_t total = uint32_t(out.size());
  std::memcpy(out.data() + 8, &total, 4);
  return out;
}

// ---- tinygltf's file access: only files inside the scene's folder, none too large ------
struct FsGuard {
  fs::path base;
};

bool guarded_exists(const std::string& path, void*) {
  std::error_code ec;
  return fs::exists(path, ec);
}
std::string guarded_expand(const std::string& path, void*) { return path; }
bool guarded_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  const FsGuard& g = *static_cast<FsGuard*>(user);
  std::error_code ec;
  const fs::path p = fs::weakly_canonical(path, ec);
  const std::string base = g.base.string() + "/";
  if (ec || p.string().compare(0, base.size(), base) != 0) {
    *err = "'" + path + "' is outside the scene's folder";
    return false;
  }
  const auto size = fs::file_size(p, ec);
  if (ec) {
    *err = "cannot open '" + path + "'";
    return false;
  }
  if (size > kMaxGltfBufferBytes) {
    *err = "'" + path + "' is larger than the 1 GiB limit";
    return false;
  }
  std::ifstream in(p, std::ios::binary);
  out->resize(size);
  in.read(reinterpret_cast<char*>(out->data()), std::streamsize(size));
  if (!in) {
    *err = "cannot read '" + path + "'";
    return false;
  }
  return true;
}
bool guarded_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  *err = "writing is not allowed";
  return false;
}

std::string percent_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(uint8_t(s[i + 1])) && std::isxdigit(uint8_t(s[i + 2]))) {
      out.push_back(char(std::stoi(s.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(s[i]);
    }
  }
  return out;
}

// True when arrays and objects in `text` nest deeper than `limit`. Checked on the text
// before either parser sees it: nlohmann's parser keeps its own stack, but tinygltf's walk
// of the tree it builds recurses once a level, and about 15,000 levels of `[[[...]]]` (a
// 30 KB file) overflowed the stack of the process loading it (the coordinator loads
// uploaded scenes itself). Brackets inside strings do not count.
bool nests_deeper_than(const std::string& text, size_t limit) {
  size_t depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > limit) return true;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return false;
}

}  // namespace

GltfDocument read_gltf_document(const std::string& path) {
  GltfDocument doc;
  doc.bytes = read_file(path);
  doc.binary = doc.bytes.size() >= 4 && doc.bytes.compare(0, 4, "glTF") == 0;
  const std::string glb_text = doc.binary ? glb_json(doc.bytes, path) : std::string();
  const std::string& text = doc.binary ? glb_text : doc.bytes;
  if (nests_deeper_than(text, kMaxGltfJsonDepth))
    throw SceneError(path, "JSON",
                     "arrays and objects nested deeper than " + std::to_string(kMaxGltfJsonDepth) + " levels");
  try {  // the one nlohmann parse of a load (tinygltf's own is in parse_gltf_model)
    doc.json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
    throw SceneError(path, "JSON", first_line(e.what()));
  }
  return doc;
}

std::vector<std::string> gltf_document_external_files(const nlohmann::json& j) {
  std::vector<std::string> out;
  std::set<std::string> seen;
  for (const char* key : {"buffers", "images"}) {
    if (!j.is_object() || !j.contains(key) || !j[key].is_array()) continue;
    for (const auto& item : j[key]) {
      if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) continue;
      const std::string uri = item["uri"];
      if (uri.rfind("data:", 0) == 0) continue;
      const std::string rel = percent_decode(uri);
      if (seen.insert(rel).second) out.push_back(rel);
    }
  }
  return out;
}

namespace {

// tinygltf names files by absolute path: the scene's folder goes, so that an error names
// files as the scene does (and a farm's never shows a server's path).
std::string relative_to(std::string s, const std::string& folder) {
  for (const std::string& f : {folder + "/", folder}) {
    if (f.empty()) continue;
    // Rebuilt by appends: g++ 12 warns falsely (-Wrestrict) on std::string::replace here.
    std::string out;
    size_t from = 0;
    for (size_t at; (at = s.find(f, from)) != std::string::npos; from = at + f.size())
      out.append(s, from, at - from).append(f == folder ? "." : "");
    s = out.append(s, from, std::string::npos);
  }
  return s;
}

// tinygltf's wording for a damaged file, in a user's terms (the original kept after it).
std::string plain_words(const std::string& s) {
  static const std::pair<const char*, const char*> kPlain[] = {
      {"BIN Chunk end does not aligned to a 4-byte boundary",
       "the .glb's BIN chunk length is not a multiple of 4 bytes (a damaged or hand-edited .glb)"},
      {"BIN Chunk data length exceeds the GLB size", "the .glb's BIN chunk runs past the end of the file (cut short?)"},
      {"Insufficient Chunk1(BIN) data size", "the .glb's BIN chunk is shorter than 4 bytes"},
      {"Invalid type for chunk1 data", "the .glb's second chunk is not a BIN chunk"},
      {"File size mismatch", "a buffer's file is not the size its byteLength says"},
      {"File is empty", "a buffer's file is empty"},
      {"File not found", "a file the scene names is missing"},
  };
  for (const auto& [raw, plain] : kPlain)
    if (s.find(raw) != std::string::npos) return std::string(plain) + " (" + s + ")";
  return s;
}

}  // namespace

void parse_gltf_model(GltfDocument doc, GltfContext& ctx) {
  // The JSON is parsed twice, the fewest the libraries allow: by nlohmann in
  // read_gltf_document, for the pre-checks, which must see it before tinygltf allocates
  // anything; and by tinygltf here. Debian's tinygltf 2.7 (a shared library) takes only
  // text: LoadASCIIFromString and LoadBinaryFromMemory parse it themselves (JsonParse, in
  // the private LoadFromString), and no public entry point takes a parsed document. When
  // the pre-checks change the JSON, tinygltf reads its dump instead of the file's text.
  if (precheck_gltf_json(doc.json, ctx.path, ctx.scene.warnings)) {
    std::string fixed = doc.json.dump();
    doc.bytes = doc.binary ? replace_glb_json(doc.bytes, std::move(fixed)) : std::move(fixed);
  }
  doc.json = nullptr;  // freed before tinygltf builds its own tree of the same text
  tinygltf::TinyGLTF loader;
  const fs::path folder = fs::absolute(ctx.path).parent_path();
  FsGuard guard{fs::weakly_canonical(folder)};
  tinygltf::FsCallbacks cb{guarded_exists, guarded_expand, guarded_read, guarded_write, &guard};
  loader.SetFsCallbacks(cb);
  EncodedImages images{0, ctx.max_load_bytes};
  loader.SetImageLoader(keep_image_encoded, &images);
  std::string err, warn;
  const std::string base = folder.string();
  const bool ok = doc.binary ? loader.LoadBinaryFromMemory(&ctx.model, &err, &warn,
                                                           reinterpret_cast<const unsigned char*>(doc.bytes.data()),
                                                           unsigned(doc.bytes.size()), base)
                             : loader.LoadASCIIFromString(&ctx.model, &err, &warn, doc.bytes.data(),
                                                          unsigned(doc.bytes.size()), base);
  if (!ok)
    throw SceneError(ctx.path, "", plain_words(first_line(relative_to(err.empty() ? "glTF parse error" : err, base))));
  if (!warn.empty()) ctx.scene.warnings.push_back(ctx.path + ": " + first_line(relative_to(warn, base)));
  // The buffers, held for the whole load (each within gltf_prechecks' limits).
  uint64_t buffer_bytes = 0;
  for (const tinygltf::Buffer& b : ctx.model.buffers) buffer_bytes += b.data.size();
  ctx.charge("buffers", "buffers", buffer_bytes);
  if (images.bytes > 0) ctx.charge("images", "encoded images", images.bytes);
  for (const std::string& ext : ctx.model.extensionsUsed) {
    if (const char* format = gltf_undecodable_format(ext))
      ctx.scene.warnings.push_back(ctx.path + ": " + ext + ": " + format +
                                   " textures cannot be decoded here; each texture's PNG or JPEG fallback is used");
    else if (!gltf_extension_supported(ext))
      ctx.scene.warnings.push_back(ctx.path + ": optional extension '" + ext + "' is not supported; ignored");
  }
  // Extensions objects use that extensionsUsed does not list (the spec requires it to, but
  // such files exist): not ignored silently either.
  const std::set<std::string> listed(ctx.model.extensionsUsed.begin(), ctx.model.extensionsUsed.end());
  std::set<std::string> unlisted;
  const auto look = [&](const tinygltf::ExtensionMap& m) {
    for (const auto& [name, value] : m)
      if (!listed.count(name) && !gltf_extension_supported(name) && !gltf_undecodable_format(name))
        unlisted.insert(name);
  };
  look(ctx.model.extensions);
  for (const tinygltf::Material& m : ctx.model.materials) {
    look(m.extensions);
    for (const tinygltf::TextureInfo* t : {&m.pbrMetallicRoughness.baseColorTexture,
                                           &m.pbrMetallicRoughness.metallicRoughnessTexture, &m.emissiveTexture})
      look(t->extensions);
    look(m.normalTexture.extensions);
    look(m.occlusionTexture.extensions);
  }
  for (const tinygltf::Texture& t : ctx.model.textures) look(t.extensions);
  for (const tinygltf::Node& n : ctx.model.nodes) look(n.extensions);
  for (const tinygltf::Mesh& m : ctx.model.meshes)
    for (const tinygltf::Primitive& p : m.primitives) look(p.extensions);
  for (const tinygltf::Camera& c : ctx.model.cameras) look(c.extensions);
  for (const std::string& name : unlisted)
    ctx.scene.warnings.push_back(ctx.path + ": extension '" + name +
                                 "' is used but not in extensionsUsed, and is not supported; ignored");
}

}  // namespace tessera
