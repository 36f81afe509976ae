#include "wire.h"

#include <google/protobuf/util/json_util.h>
#include <xxhash.h>
#include <zstd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

namespace tessera {

namespace fs = std::filesystem;

v1::RenderSettings to_proto(const RenderSettings& s) {
  v1::RenderSettings p;
  p.set_spp(uint32_t(s.spp));
  p.set_light_samples(uint32_t(s.light_samples));
  p.set_max_depth(uint32_t(s.max_depth));
  p.set_adaptive(s.adaptive);
  p.set_adaptive_batch(uint32_t(s.adaptive_batch));
  p.set_adaptive_tolerance(s.adaptive_tolerance);
  p.set_seed(s.seed);
  p.set_pass_spp(uint32_t(s.pass_spp));
  p.set_width(uint32_t(s.camera.width));
  p.set_height(uint32_t(s.camera.height));
  p.set_lens_radius(s.camera.lens_radius);
  p.set_focal_distance(s.camera.focal_distance);
  p.set_framing(s.camera.framing == Framing::kFile ? v1::RenderSettings::FILE : v1::RenderSettings::CS184);
  *p.mutable_window() = to_proto(s.window);
  return p;
}

RenderSettings from_proto(const v1::RenderSettings& p) {
  auto check = [](bool ok, const char* what) {
    if (!ok) throw WireError(std::string("render settings: ") + what);
  };
  check(p.spp() >= 1 && p.spp() <= (1u << 24), "spp must be in 1..16777216");
  check(p.light_samples() >= 1 && p.light_samples() <= (1u << 16), "light samples must be in 1..65536");
  check(p.max_depth() <= (1u << 16), "max depth too large");
  check(p.width() >= 1 && p.width() <= 65536 && p.height() >= 1 && p.height() <= 65536, "size must be in 1..65536");
  check(p.pass_spp() >= 1 && p.pass_spp() <= (1u << 24), "pass spp must be in 1..16777216");
  check(!p.adaptive() || (p.adaptive_batch() >= 1 && p.adaptive_tolerance() >= 0), "bad adaptive parameters");
  check(std::isfinite(p.lens_radius()) && p.lens_radius() >= 0, "lens radius must be >= 0");
  check(std::isfinite(p.focal_distance()) && p.focal_distance() > 0, "focal distance must be > 0");
  RenderSettings s;
  s.spp = int(p.spp());
  s.light_samples = int(p.light_samples());
  s.max_depth = int(p.max_depth());
  s.adaptive = p.adaptive();
  s.adaptive_batch = int(p.adaptive_batch());
  s.adaptive_tolerance = p.adaptive_tolerance();
  s.seed = p.seed();
  s.pass_spp = int(p.pass_spp());
  s.camera.width = int(p.width());
  s.camera.height = int(p.height());
  s.camera.lens_radius = p.lens_radius();
  s.camera.focal_distance = p.focal_distance();
  s.camera.framing = p.framing() == v1::RenderSettings::FILE ? Framing::kFile : Framing::kCs184;
  s.window = from_proto(p.window());
  if (s.window.area() > 0)
    check(int64_t(s.window.x) + s.window.w <= s.camera.width && int64_t(s.window.y) + s.window.h <= s.camera.height,
          "window outside the image");
  return s;
}

v1::Rect to_proto(const Rect& r) {
  v1::Rect p;
  p.set_x(uint32_t(r.x));
  p.set_y(uint32_t(r.y));
  p.set_w(uint32_t(r.w));
  p.set_h(uint32_t(r.h));
  return p;
}

Rect from_proto(const v1::Rect& r) {
  if (r.x() > 65536 || r.y() > 65536 || r.w() > 65536 || r.h() > 65536) throw WireError("rectangle out of range");
  return Rect{int(r.x()), int(r.y()), int(r.w()), int(r.h())};
}

std::string read_file_bytes(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::runtime_error(p + ": cannot open file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string proto_json(const google::protobuf::Message& m) {
  google::protobuf::util::JsonPrintOptions o;
  o.always_print_primitive_fields = true;
  o.preserve_proto_field_names = true;
  std::string s;
  (void)google::protobuf::util::MessageToJsonString(m, &s, o);
  return s;
}

std::string encode_sums(const std::vector<PixelSums>& sums) {
  std::string raw(sums.size() * kBytesPerPixel, '\0');
  char* out = raw.data();
  for (const PixelSums& p : sums) {  // x86-64 is little-endian, as the format says
    std::memcpy(out, &p.r, 8);
    std::memcpy(out + 8, &p.g, 8);
    std::memcpy(out + 16, &p.b, 8);
    std::memcpy(out + 24, &p.lum2, 8);
    std::memcpy(out + 32, &p.n, 4);
    out += kBytesPerPixel;
  }
  std::string compressed(ZSTD_compressBound(raw.size()), '\0');
  const size_t n = ZSTD_compress(compressed.data(), compressed.size(), raw.data(), raw.size(), 1);
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  compressed.resize(n);
  return compressed;
}

std::vector<PixelSums> decode_sums(const std::string& compressed, size_t pixels) {
  const size_t want = pixels * kBytesPerPixel;
  const unsigned long long declared = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) throw WireError("sums: not zstd data");
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != want)
    throw WireError("sums: " + std::to_string(declared) + " bytes declared, " + std::to_string(want) + " expected");
  std::string raw(want, '\0');
  const size_t n = ZSTD_decompress(raw.data(), raw.size(), compressed.data(), compressed.size());
  if (ZSTD_isError(n)) throw WireError(std::string("sums: ") + ZSTD_getErrorName(n));
  if (n != want) throw WireError("sums: " + std::to_string(n) + " bytes, " + std::to_string(want) + " expected");
  std::vector<PixelSums> sums(pixels);
  const char* in = raw.data();
  for (PixelSums& p : sums) {
    std::memcpy(&p.r, in, 8);
    std::memcpy(&p.g, in + 8, 8);
    std::memcpy(&p.b, in + 16, 8);
    std::memcpy(&p.lum2, in + 24, 8);
    std::memcpy(&p.n, in + 32, 4);
    if (!std::isfinite(p.r) || !std::isfinite(p.g) || !std::isfinite(p.b) || !std::isfinite(p.lum2))
      throw WireError("sums: non-finite value");
    in += kBytesPerPixel;
  }
  return sums;
}

std::string bundle_hash(const std::string& main_file, const google::protobuf::RepeatedPtrField<v1::SceneFile>& files) {
  XXH3_state_t* st = XXH3_createState();
  XXH3_128bits_reset(st);
  auto add = [&](const std::string& s) {
    const uint64_t n = s.size();
    XXH3_128bits_update(st, &n, sizeof n);
    XXH3_128bits_update(st, s.data(), s.size());
  };
  add(main_file);
  for (const v1::SceneFile& f : files) {
    add(f.path());
    add(f.content());
  }
  const XXH128_hash_t h = XXH3_128bits_digest(st);
  XXH3_freeState(st);
  char buf[33];
  std::snprintf(buf, sizeof buf, "%016llx%016llx", (unsigned long long)h.high64, (unsigned long long)h.low64);
  return buf;
}

namespace {

bool safe_relative(const std::string& p) {
  if (p.empty() || p.size() > 1024 || p[0] == '/' || p.find('\0') != std::string::npos) return false;
  for (const auto& part : fs::path(p))
    if (part == ".." || part == ".") return false;
  return true;
}

}  // namespace

std::string unpack_bundle(const std::string& dir, const std::string& main_file,
                          const google::protobuf::RepeatedPtrField<v1::SceneFile>& files) {
  bool has_main = false;
  for (const v1::SceneFile& f : files) {
    if (!safe_relative(f.path())) throw WireError("scene bundle: unsafe file path '" + f.path() + "'");
    has_main |= f.path() == main_file;
  }
  if (!has_main) throw WireError("scene bundle: main file '" + main_file + "' is not among its files");
  fs::create_directories(dir);
  for (const v1::SceneFile& f : files) {
    const fs::path p = fs::path(dir) / f.path();
    fs::create_directories(p.parent_path());
    const std::string tmp = p.string() + ".tmp";
    {
      std::ofstream out(tmp, std::ios::binary);
      out.write(f.content().data(), std::streamsize(f.content().size()));
      if (!out) throw std::runtime_error(p.string() + ": cannot write");
    }
    fs::rename(tmp, p);
  }
  return (fs::path(dir) / main_file).string();
}

namespace {

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

// The external files (buffers, images) a glTF document names, as relative paths.
std::vector<std::string> gltf_references(const std::string& path, const std::string& bytes) {
  std::string json_text = bytes;
  if (bytes.size() >= 20 && bytes.compare(0, 4, "glTF") == 0) {  // .glb: the JSON chunk
    uint32_t len;
    std::memcpy(&len, bytes.data() + 12, 4);
    if (uint64_t(len) + 20 > bytes.size())
      throw std::runtime_error(path + ": GLB chunk 0 runs past the end of the file");
    json_text = bytes.substr(20, len);
  }
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(json_text);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": JSON: " + e.what());
  }
  std::vector<std::string> out;
  for (const char* key : {"buffers", "images"}) {
    if (!j.contains(key) || !j[key].is_array()) continue;
    for (const auto& item : j[key]) {
      if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) continue;
      const std::string uri = item["uri"];
      if (uri.rfind("data:", 0) == 0) continue;
      out.push_back(percent_decode(uri));
    }
  }
  return out;
}

}  // namespace

void pack_scene(const std::string& path, std::string* main_file,
                google::protobuf::RepeatedPtrField<v1::SceneFile>* files) {
  const std::string bytes = read_file_bytes(path);
  *main_file = fs::path(path).filename().string();
  v1::SceneFile* f = files->Add();
  f->set_path(*main_file);
  f->set_content(bytes);
  // CS184 COLLADA scenes are self-contained; glTF names buffers and images beside it.
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(uint8_t(c)));
  if (ext != ".gltf" && ext != ".glb") return;
  std::set<std::string> seen;
  for (const std::string& rel : gltf_references(path, bytes)) {
    if (!safe_relative(rel)) throw std::runtime_error(path + ": '" + rel + "' is not a path inside the scene's folder");
    if (!seen.insert(rel).second) continue;
    v1::SceneFile* extra = files->Add();
    extra->set_path(rel);
    extra->set_content(read_file_bytes((fs::path(path).parent_path() / rel).string()));
  }
}

}  // namespace tessera
