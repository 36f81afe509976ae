// The `tessera` executable as a user runs it: outputs, metadata, stats, and errors.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "tests/integration/farm_helpers.h"

namespace {

namespace fs = std::filesystem;

struct CommandResult {
  int code = -1;
  std::string out, err;
};

// A shell command line (its programs named relative to the build's bin folder by the
// caller), with its exit code and output.
CommandResult run_line(const std::string& line) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_cli_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string out = (dir / "out.txt").string(), err = (dir / "err.txt").string();
  const std::string cmd = line + " >" + out + " 2>" + err;
  const int status = std::system(cmd.c_str());
  CommandResult r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const std::string& p) {
    std::ifstream f(p);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  };
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

CommandResult run(const std::string& args) { return run_line(std::string(TESSERA_BIN_DIR) + "/tessera " + args); }

class Cli : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_cli_out_" + std::to_string(::getpid()));
  std::string scene = std::string(TESSERA_SOURCE_DIR) + "/scenes/cornell-spheres.dae";
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(Cli, RendersExrWithSppVarianceAndMetadataAndAPngAndStats) {
  const std::string exr = (dir / "a.exr").string(), png = (dir / "a.png").string(), json = (dir / "s.json").string();
  const CommandResult r =
      run("render " + scene + " -s 4 -r 40 30 -m 3 --seed 5 -q -f " + exr + " -f " + png + " --stats-json " + json);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("samples/s"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("rays/s"), std::string::npos) << r.out;
  const tessera::ExrImage img = tessera::read_exr(exr);
  EXPECT_EQ(img.width, 40);
  EXPECT_EQ(img.height, 30);
  for (const char* ch : {"R", "G", "B", "spp", "variance"}) EXPECT_TRUE(img.channels.count(ch)) << ch;
  for (float n : img.channels.at("spp")) ASSERT_EQ(n, 4.0f);
  for (float v : img.channels.at("variance")) ASSERT_GE(v, 0.0f);
  EXPECT_EQ(img.metadata.at("tessera/seed"), "5");
  EXPECT_NE(img.metadata.at("tessera/flags").find("-m 3"), std::string::npos);
  EXPECT_NE(img.metadata.at("tessera/scene").find("cornell-spheres.dae"), std::string::npos);
  EXPECT_TRUE(img.metadata.count("tessera/render_seconds"));
  EXPECT_GT(fs::file_size(png), 100u);
  std::ifstream jf(json);
  const nlohmann::json j = nlohmann::json::parse(jf);
  EXPECT_EQ(j.at("samples").get<uint64_t>(), 40u * 30u * 4u);
  EXPECT_GT(j.at("rays_per_second").get<double>(), 0);
  EXPECT_EQ(j.at("nan_samples").get<uint64_t>(), 0u);
}

// Issue 28: --light-tracer, and --stats-json saying which ran and why.
TEST_F(Cli, LightTracingIsChosenAndReported) {
  const std::string json = (dir / "lt.json").string(), exr = (dir / "lt.exr").string();
  const auto stats = [&](const std::string& flags) {
    const CommandResult r = run("render " + scene + " -s 4 -r 40 30 -q -f " + exr + " --stats-json " + json + flags);
    EXPECT_EQ(r.code, 0) << flags << ": " << r.err;
    std::ifstream jf(json);
    return nlohmann::json::parse(jf);
  };
  const nlohmann::json on = stats(" --light-tracer auto");  // the glass and mirror spheres
  EXPECT_TRUE(on.at("light_tracer").get<bool>()) << on.dump();
  EXPECT_EQ(on.at("light_paths").get<uint64_t>(), 40u * 30u * 4u / 4u);
  EXPECT_EQ(on.at("dropped_splats").get<uint64_t>(), 0u);
  const nlohmann::json adaptive = stats(" --light-tracer auto -a 2 0.05");
  EXPECT_FALSE(adaptive.at("light_tracer").get<bool>());
  EXPECT_NE(adaptive.at("light_tracer_why").get<std::string>().find("-a"), std::string::npos) << adaptive.dump();
  const nlohmann::json by_default = stats("");  // auto
  EXPECT_TRUE(by_default.at("light_tracer").get<bool>()) << by_default.dump();
  const nlohmann::json off = stats(" --light-tracer off");
  EXPECT_FALSE(off.at("light_tracer").get<bool>());
  EXPECT_EQ(off.at("light_paths").get<uint64_t>(), 0u);
  const CommandResult refused = run("render " + scene + " -s 4 -r 8 8 -q --light-tracer on -a 2 0.05");
  EXPECT_NE(refused.code, 0);
  EXPECT_NE(refused.err.find("--light-tracer"), std::string::npos) << refused.err;
  EXPECT_EQ(run("render " + scene + " --light-tracer sometimes").code, 2);
}

// Issue 12: a sequence renders each frame as `--frame N` alone would, to its own files.
TEST_F(Cli, FramesRenderASequenceEachFrameAsItsOwnRenderWould) {
  const std::string pattern = (dir / "seq.##.exr").string();
  CommandResult r = run("render " + scene + " -s 2 -r 24 16 --frames 1-5x2 -q -f " + pattern);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"seq.01.exr", "seq.03.exr", "seq.05.exr"}) EXPECT_TRUE(fs::exists(dir / f)) << f;
  EXPECT_FALSE(fs::exists(dir / "seq.02.exr"));
  const std::string alone = (dir / "alone.exr").string();
  ASSERT_EQ(run("render " + scene + " -s 2 -r 24 16 --frame 3 -q -f " + alone).code, 0);
  tessera::testing::expect_same_pixels(alone, (dir / "seq.03.exr").string());
  EXPECT_EQ(tessera::read_exr((dir / "seq.05.exr").string()).metadata.at("tessera/frame"), "5");
  // Several frames into one file would overwrite each other: refused before rendering.
  r = run("render " + scene + " -s 2 -r 24 16 --frames 1-2 -q -f " + (dir / "one.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("need a #### in every -f path"), std::string::npos) << r.err;
  r = run("render " + scene + " --frames 3-1 -q -f " + pattern);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--frames: '3-1': the range runs backwards"), std::string::npos) << r.err;
}

TEST_F(Cli, ABadCameraPathOrAnimationIsRefusedNamingTheFileKeyAndField) {
  const std::string path = (dir / "pull.json").string();
  std::ofstream(path) << R"({"keys": [{"frame": 5, "focal_distance": 3}, {"frame": 2, "focal_distance": 4}]})";
  CommandResult r = run("render " + scene + " -s 1 -r 8 8 --frames 1-3 --camera-path " + path + " -q -f " +
                        (dir / "x.####.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--camera-path: " + path + ": key 2: frame 2.0 does not come after"), std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir / "x.0001.exr"));  // refused before anything is rendered
  r = run("render " + scene + " -s 1 -r 8 8 --turntable nan -q -f " + (dir / "t.exr").string());
  EXPECT_NE(r.code, 0);
  r = run("render " + std::string(TESSERA_SOURCE_DIR) + "/scenes/cornell-animated.gltf -s 1 -r 8 8 --frame 3 " +
          "--animation walk -q -f " + (dir / "a.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--animation: no animation 'walk' (the scene has 0 'move')"), std::string::npos) << r.err;
}

// Found by audit: a path whose eye crossed its target at frame 5 wrote frames 1 to 4 and then
// failed; a seed past 64 bits, a fractional -a batch and a sequence's one --stats-json file
// were taken silently (the seed saturated, the batch was cut, the file overwritten a frame).
TEST_F(Cli, ASequenceIsCheckedAtEveryFrameAndNoValueIsTakenForAnother) {
  const std::string path = (dir / "cross.json").string();
  std::ofstream(path) << R"({"keys": [{"frame": 0, "eye": [0, 0.5, 3], "target": [0, 0.5, 0]},
                                     {"frame": 10, "eye": [0, 0.5, -3], "target": [0, 0.5, 0]}]})";
  CommandResult r = run("render " + scene + " -s 1 -r 8 8 --frames 1-6 --camera-path " + path + " -q -f " +
                        (dir / "c.####.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--camera-path: at frame 5: the camera is degenerate"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "c.0001.exr"));  // refused before anything is rendered
  const std::string out = " -q -f " + (dir / "s.exr").string();
  for (const char* seed : {"-1", "18446744073709551616", "1e23", "x"}) {
    r = run("render " + scene + " -s 1 -r 8 8 --seed " + seed + out);
    EXPECT_EQ(r.code, 2) << seed;
    EXPECT_NE(r.err.find("must be a whole number in 0..18446744073709551615"), std::string::npos) << r.err;
  }
  r = run("render " + scene + " -s 1 -r 8 8 --seed 18446744073709551615" + out);
  EXPECT_EQ(r.code, 0) << r.err;
  r = run("render " + scene + " -s 4 -r 8 8 -a 2.7 0.1" + out);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("-a"), std::string::npos) << r.err;
  r = run("render " + scene + " -s 1 -r 8 8 --frames 1-2 --stats-json " + (dir / "st.json").string() + " -q -f " +
          (dir / "f.####.exr").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--stats-json: several frames need a #### in its path"), std::string::npos) << r.err;
}

TEST_F(Cli, ABrokenEnvironmentMapIsRefusedNamingTheFile) {
  const std::string bad = (dir / "bad.hdr").string();
  std::ofstream(bad) << "not radiance";
  const CommandResult r = run("render " + scene + " -s 1 -r 8 8 --env " + bad + " -q -f " + (dir / "e.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--env: " + bad + ": not a Radiance HDR image"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "e.exr"));
}

// The cell's pixels alone, in their place in the frame: the EXR's data window is the cell
// (-p counts rows from the bottom, EXR from the top: rows 48 - (4 + 12) = 32 to 43) and its
// display window the whole 64 x 48 image, as a compositor expects of a crop. The PNG (no
// such windows) holds the cell.
TEST_F(Cli, CellRenderingWritesOnlyTheCellInItsPlace) {
  const std::string exr = (dir / "cell.exr").string(), png = (dir / "cell.png").string();
  const CommandResult r = run("render " + scene + " -s 2 -r 64 48 -p 8 4 16 12 -q -f " + exr + " -f " + png);
  ASSERT_EQ(r.code, 0) << r.err;
  const tessera::ExrImage img = tessera::read_exr(exr);
  EXPECT_EQ(img.width, 16);
  EXPECT_EQ(img.height, 12);
  const Imf::InputFile file(exr.c_str());
  EXPECT_EQ(file.header().dataWindow(), Imath::Box2i({8, 32}, {23, 43}));
  EXPECT_EQ(file.header().displayWindow(), Imath::Box2i({0, 0}, {63, 47}));
  const std::string bytes = tessera::read_file_bytes(png);  // the IHDR's width and height (big-endian)
  ASSERT_GE(bytes.size(), 24u);
  const auto be32 = [&](size_t at) {
    return (uint32_t(uint8_t(bytes[at])) << 24) | (uint32_t(uint8_t(bytes[at + 1])) << 16) |
           (uint32_t(uint8_t(bytes[at + 2])) << 8) | uint8_t(bytes[at + 3]);
  };
  EXPECT_EQ(be32(16), 16u);
  EXPECT_EQ(be32(20), 12u);
  // The same render with --denoise keeps the place (the denoiser keeps an input's windows).
  const std::string denoised = (dir / "cell-denoised.exr").string();
  ASSERT_EQ(run("render " + scene + " -s 2 -r 64 48 -p 8 4 16 12 -q --denoise -f " + denoised).code, 0);
  EXPECT_EQ(Imf::InputFile(denoised.c_str()).header().dataWindow(), Imath::Box2i({8, 32}, {23, 43}));
}

TEST_F(Cli, MalformedSceneGivesOneLineNamingTheFileAndExitsNonZero) {
  const std::string bad = (dir / "broken.dae").string();
  std::ofstream(bad) << "<COLLADA><scene><instance_visual_scene url=\"#nowhere\"/></scene></COLLADA>";
  const CommandResult r = run("render " + bad + " -q -f " + (dir / "x.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("broken.dae"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("dangling reference '#nowhere'"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(dir / "x.exr"));
}

// Issue 10, row 1: `tessera render` aborted in Embree (SIGABRT) on a vertex at 1e20.
TEST_F(Cli, GeometryOutOfRangeIsAnErrorNotACrash) {
  std::ifstream in(std::string(TESSERA_SOURCE_DIR) + "/scenes/cornell-spheres.dae");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string wall = "-1 -0.75 -1 -1 -0.75 1";
  ASSERT_NE(text.find(wall), std::string::npos);
  text.replace(text.find(wall), 2, "99999999999999999999");
  const std::string bad = (dir / "far.dae").string();
  std::ofstream(bad) << text;
  const CommandResult r = run("render " + bad + " -q -s 1 -r 8 8 -f " + (dir / "x.exr").string());
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("far.dae: mesh '"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("outside +-1e12"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST_F(Cli, BadFlagsAreRefused) {
  EXPECT_NE(run("render " + scene + " -r 0 10").code, 0);
  EXPECT_NE(run("render " + scene + " -p 60 0 20 20 -r 64 48").code, 0);
  EXPECT_NE(run("render " + scene + " --camera sideways").code, 0);
  EXPECT_NE(run("render /no/such/file.dae").code, 0);
  EXPECT_NE(run("render " + scene + " -q -s 1 -r 8 8 -f " + (dir / "x.bmp").string()).code, 0);
  // The one range check names the flag, for render and submit alike.
  for (const std::string cmd : {"render ", "submit "})
    for (const auto& [flags, named] : std::vector<std::pair<std::string, std::string>>{
             {" -s 0", "-s"}, {" --tile 0", "--tile"}, {" --noise-target -1", "--noise-target"}, {" -a 0 0.1", "-a"}}) {
      const auto r = run(cmd + scene + flags + (cmd == "submit " ? " --coordinator 127.0.0.1:1" : ""));
      EXPECT_NE(r.code, 0) << cmd << flags;
      EXPECT_NE(r.err.find(named), std::string::npos) << cmd << flags << ": " << r.err;
    }
}

// As the tools operators know: --version on every binary (the commit it was built from),
// exit code 2 for a usage error (CLI11's own codes are 100 and up), 0 for --help.
TEST_F(Cli, EveryBinaryHasVersionAndAUsageErrorExitsTwo) {
  for (const std::string bin : {"tessera", "tessera-coordinator", "tessera-worker", "tessera-wan-proxy"}) {
    const std::string path = std::string(TESSERA_BIN_DIR) + "/" + bin;
    if (!fs::exists(path)) continue;  // (the relay is built with the tests and benches)
    const CommandResult v = run_line(path + " --version");
    EXPECT_EQ(v.code, 0) << bin << ": " << v.err;
    EXPECT_EQ(v.out.rfind(bin + " ", 0), 0u) << v.out;
    EXPECT_GT(v.out.size(), bin.size() + 2) << v.out;  // and a version after the name
    const CommandResult bad = run_line(path + " --no-such-flag");
    EXPECT_EQ(bad.code, 2) << bin << ": " << bad.err;
    EXPECT_NE(bad.err.find("Run with --help"), std::string::npos) << bad.err;  // and what is wrong
  }
  EXPECT_EQ(run("render").code, 2);  // the scene is missing
  EXPECT_EQ(run("render " + scene + " --frames 3-1").code, 2);
  EXPECT_EQ(run("--help").code, 0);
}

// One spelling per option: threads are -t or --threads for tessera render and the worker.
TEST_F(Cli, ThreadsAreSpelledAlikeEverywhere) {
  EXPECT_EQ(run("render " + scene + " -s 1 -r 16 12 -q --threads 1 -f " + (dir / "a.exr").string()).code, 0);
  EXPECT_EQ(run("render " + scene + " -s 1 -r 16 12 -q -t 1 -f " + (dir / "b.exr").string()).code, 0);
  const std::string worker = std::string(TESSERA_BIN_DIR) + "/tessera-worker";
  for (const std::string flag : {"-t", "--threads"}) {
    const CommandResult h = run_line(worker + " --help");
    EXPECT_NE(h.out.find("-t,--threads"), std::string::npos) << h.out;
    // A bad count is refused naming the option under either spelling (so both parse).
    const CommandResult bad = run_line(worker + " --coordinator 127.0.0.1:1 " + flag + " -3");
    EXPECT_EQ(bad.code, 2) << bad.err;
    EXPECT_NE(bad.err.find("threads"), std::string::npos) << bad.err;
  }
}

// $TESSERA_COORDINATOR names the coordinator for every farm command (and the worker).
TEST_F(Cli, TesseraCoordinatorNamesTheCoordinator) {
  const CommandResult r = run_line("TESSERA_COORDINATOR=127.0.0.1:1 " + std::string(TESSERA_BIN_DIR) + "/tessera jobs");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("coordinator 127.0.0.1:1 unreachable"), std::string::npos) << r.err;
  // A flag still wins over the variable.
  const CommandResult f = run_line("TESSERA_COORDINATOR=127.0.0.1:1 " + std::string(TESSERA_BIN_DIR) +
                                   "/tessera jobs --coordinator 127.0.0.1:2");
  EXPECT_NE(f.err.find("coordinator 127.0.0.1:2 unreachable"), std::string::npos) << f.err;
}

// Outputs are checked before the render: a missing folder is made, an unknown format is a
// usage error at once (not after the whole render).
TEST_F(Cli, OutputsAreCheckedBeforeTheRender) {
  const fs::path deep = dir / "new" / "folder" / "a.exr";
  CommandResult r = run("render " + scene + " -s 1 -r 16 12 -q -f " + deep.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(deep));
  r = run("render " + scene + " -s 100000 -r 1920 1080 -q -f " + (dir / "a.tif").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("a.tif: unknown image format (use .exr or .png)"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "a.tif"));
}

// A sequence's frames go into folders named by their number: made as each is written (the
// folder's #### kept it from being made, and no frame was written; found by audit).
TEST_F(Cli, FramesGoIntoFoldersNamedByTheirNumber) {
  const CommandResult r =
      run("render " + scene + " -s 1 -r 16 12 -q --frames 1-2 -f " + (dir / "frames" / "####" / "a.png").string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "frames" / "0001" / "a.png"));
  EXPECT_TRUE(fs::exists(dir / "frames" / "0002" / "a.png"));
}

// Two images of two pixels, (1, 1, 1) and (2, 2, 2); the second's last red is NaN.
void write_two_pixels(const std::string& a, const std::string& nan) {
  tessera::Film film(tessera::Rect{0, 0, 2, 1});
  film.at(0, 0) = tessera::PixelSums{1, 1, 1, 0, 1};
  film.at(1, 0) = tessera::PixelSums{2, 2, 2, 0, 1};
  tessera::write_exr(a, film, {});
  film.at(1, 0) = tessera::PixelSums{NAN, 2, 2, 0, 1};
  tessera::write_exr(nan, film, {});
}

// tessera_compare names what it lacks (it said "map::at") and compares only pixels finite
// in both images (a NaN in the reference gave null figures and exit 0).
TEST_F(Cli, CompareNamesAMissingChannelAndSkipsNonFinitePixelsOfEither) {
  const std::string a = (dir / "a.exr").string(), y = (dir / "y.exr").string(), nan = (dir / "nan.exr").string();
  write_two_pixels(a, nan);
  {  // grey: Y alone
    float grey[2] = {1, 2};
    Imf::Header header(2, 1);
    header.channels().insert("Y", Imf::Channel(Imf::FLOAT));
    Imf::FrameBuffer fb;
    fb.insert("Y", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(grey), sizeof(float), 2 * sizeof(float)));
    Imf::OutputFile file(y.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(1);
  }
  const std::string bin = std::string(TESSERA_BIN_DIR) + "/tessera_compare ";
  CommandResult r = run_line(bin + a + " " + y);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find(y + " has no channel R"), std::string::npos) << r.err;
  r = run_line(bin + a + " " + nan);
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["nonfinite"], 1);
  EXPECT_EQ(j["rmse"], 0);
}

// Found by audit: a region's figures took NaN pixels in (null figures, exit 0), a region
// 2^31 wide passed the bounds check by overflow and crashed, and the same pixels elsewhere
// in the frame (another data window) compared "identical".
TEST_F(Cli, CompareRegionsSkipNonFinitePixelsAndRefuseWhatIsNotInTheImage) {
  const std::string a = (dir / "a.exr").string(), nan = (dir / "nan.exr").string();
  const std::string moved = (dir / "moved.exr").string(), regions = (dir / "regions.json").string();
  write_two_pixels(a, nan);
  {
    float v[2] = {1, 2};
    Imf::Header header(Imath::Box2i({0, 0}, {200, 100}), Imath::Box2i({100, 50}, {101, 50}));
    Imf::FrameBuffer fb;
    for (const char* c : {"R", "G", "B"}) {
      header.channels().insert(c, Imf::Channel(Imf::FLOAT));
      // Where pixel (0, 0) would be (OpenEXR addresses the data window's pixels from it).
      char* origin = reinterpret_cast<char*>(reinterpret_cast<uintptr_t>(v) - (100 + 50 * 2) * sizeof(float));
      fb.insert(c, Imf::Slice(Imf::FLOAT, origin, sizeof(float), 2 * sizeof(float)));
    }
    Imf::OutputFile file(moved.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(1);
  }
  const std::string bin = std::string(TESSERA_BIN_DIR) + "/tessera_compare ";
  tessera::write_file_atomic(regions, R"({"all": [0, 0, 2, 1]})");
  CommandResult r = run_line(bin + a + " " + nan + " --regions " + regions);
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["regions"]["all"]["relmse"], 0);
  EXPECT_EQ(j["regions"]["all"]["nonfinite"], 1);
  EXPECT_EQ(j["regions"]["all"]["image"][0], 1);
  tessera::write_file_atomic(regions, R"({"wide": [10, 0, 2147483647, 1]})");
  r = run_line(bin + a + " " + a + " --regions " + regions);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("region 'wide' is not inside the image"), std::string::npos) << r.err;
  tessera::write_file_atomic(regions, R"({"short": [1, 1, 2]})");
  r = run_line(bin + a + " " + a + " --regions " + regions);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("region 'short' is not [x, y, w, h] in whole pixels"), std::string::npos) << r.err;
  r = run_line(bin + moved + " " + a);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("data windows start at different pixels: (100, 50) against (0, 0)"), std::string::npos) << r.err;
}

}  // namespace

namespace {

// Found by audit: an output that could not be written (a folder in its place) lost the
// outputs after it, the render thrown away; each is now written if it can be, the failures
// said together. A frame's time is written exactly (--fps 700000 kept 6 decimals:
// "0.000001", 30% off), and an fps whose frame times are not finite is refused; the
// warning of an unlit glTF scene no longer says a default environment lights it under
// --no-default-env.
TEST_F(Cli, EveryOutputThatCanBeWrittenIsAndAFramesTimeIsExact) {
  fs::create_directories(dir / "taken.png");
  const std::string kept = (dir / "kept.exr").string();
  CommandResult r =
      run("render " + scene + " -s 1 -r 16 12 -m 1 -q -f " + (dir / "taken.png").string() + " -f " + kept);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("taken.png"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::exists(kept));
  const std::string timed = (dir / "timed.exr").string();
  r = run("render " + scene + " -s 1 -r 8 6 -m 1 -q --fps 700000 --frame 1 -f " + timed);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(tessera::read_exr(timed).metadata.at("tessera/time"), "1.4285714285714286e-06");
  r = run("render " + scene + " -s 1 -r 8 6 -q --fps 5e-324 --frame 1 -f " + timed);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--fps"), std::string::npos) << r.err;
  const std::string unlit = std::string(TESSERA_SOURCE_DIR) + "/scenes/skinned-bar.gltf";  // (no light)
  r = run("render " + unlit + " -s 1 -r 8 6 -m 1 --no-default-env -f " + (dir / "unlit.exr").string());
  EXPECT_EQ(r.err.find("neutral default environment"), std::string::npos) << r.err;
  r = run("render " + unlit + " -s 1 -r 8 6 -m 1 -f " + (dir / "unlit.exr").string());  // (said where it is so)
  EXPECT_NE(r.err.find("neutral default environment"), std::string::npos) << r.err;
}

}  // namespace
