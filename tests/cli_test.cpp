// The command line as a user meets it: bad input ends with one line naming the file and the
// problem, exit code 2 and no output file; the project's scenes are what its tool generates.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "core/image.h"
#include "test_support.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

CommandResult run(const std::string& args) {
  const std::string command = std::string(MOBIRT_EXE) + " " + args + " 2>&1";
  CommandResult r;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buffer;
  size_t n;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) r.output.append(buffer.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string quoted(const fs::path& p) {
  std::string q(1, '\'');  // appended: GCC 12 warns falsely (-Wrestrict) on "'" + s
  return q.append(p.string()).append(1, '\'');
}

// A bad input: exit 2, one line on the output naming `names`, and no output file left behind.
void expect_refused(const std::string& args, const fs::path& output, const std::string& names) {
  const CommandResult r = run(args + " -o " + quoted(output));
  SCOPED_TRACE(args);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find("mobirt: error: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(names), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(output));
  // Nor a temporary file beside it.
  if (!fs::is_directory(output.parent_path())) return;
  for (const auto& entry : fs::directory_iterator(output.parent_path())) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp"), std::string::npos) << entry.path();
  }
}

TEST(Cli, RendersTheDefaultScene) {
  const fs::path dir = test::temp_dir();
  const CommandResult r = run("render " MOBIRT_SOURCE_DIR "/scenes/default.gltf --size 64x40 -o " + quoted(dir / "a.png"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir / "a.png"));
  const Image image = read_image((dir / "a.png").string());
  EXPECT_EQ(image.width, 64);
  EXPECT_EQ(image.height, 40);
}

TEST(Cli, BadInputIsRefusedWithoutOutput) {
  const fs::path dir = test::temp_dir();
  const fs::path out = dir / "out.png";
  const std::string scene = MOBIRT_SOURCE_DIR "/scenes/default.gltf";
  expect_refused("render " + quoted(dir / "missing.gltf"), out, "missing.gltf");
  {
    std::ofstream(dir / "broken.gltf") << "{ \"asset\": { \"version\": \"2.0\" }, \"meshes\": [ ";
    expect_refused("render " + quoted(dir / "broken.gltf"), out, "broken.gltf");
  }
  {
    std::ofstream(dir / "lines.gltf") << R"({"asset":{"version":"2.0"},
      "buffers":[{"byteLength":24,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAA"}],
      "bufferViews":[{"buffer":0,"byteLength":24}],
      "accessors":[{"bufferView":0,"componentType":5126,"count":2,"type":"VEC3","min":[0,0,0],"max":[1,0,0]}],
      "meshes":[{"primitives":[{"attributes":{"POSITION":0},"mode":1}]}],
      "nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}],"scene":0})";
    expect_refused("render " + quoted(dir / "lines.gltf"), out, "LINES");
  }
  expect_refused("render " + scene + " --light 'point pos=1,2'", out, "--light");
  expect_refused("render " + scene + " --camera '0,0,0:0,0,0:0,1,0:45'", out, "--camera");
  expect_refused("render " + scene + " --size 0x10", out, "--size");
  expect_refused("render " + scene + " --stack 99", out, "--stack");
  expect_refused("render " + scene + " --bogus", out, "--bogus");
  expect_refused("render " + scene + " --device no-such-device", out, "no-such-device");
  expect_refused("render " + scene + " --light 'point pos=0,5,0' --light 'point pos=1,5,0' "
                 "--light 'point pos=2,5,0' --light 'point pos=3,5,0' --light 'point pos=4,5,0' "
                 "--light 'point pos=5,5,0' --light 'point pos=6,5,0' --light 'point pos=7,5,0' "
                 "--light 'point pos=8,5,0' --light 'point pos=9,5,0' --light 'point pos=10,5,0' "
                 "--light 'point pos=11,5,0' --light 'point pos=12,5,0' --light 'point pos=13,5,0' "
                 "--light 'point pos=14,5,0' --light 'point pos=15,5,0' --light 'point pos=16,5,0'",
                 out, "17 lights");
  // An output the user cannot get: unknown format, missing folder.
  expect_refused("render " + scene, dir / "out.unknownformat", "out.unknownformat");
  expect_refused("render " + scene, dir / "no-such-folder" / "out.png", "no-such-folder");
}

TEST(Cli, HelpAndInfo) {
  for (const char* args : {"--help", "render --help", "info --help"}) {
    const CommandResult r = run(args);
    EXPECT_EQ(r.exit_code, 0) << args;
    EXPECT_NE(r.output.find("Usage"), std::string::npos) << r.output;
  }
  const CommandResult info = run("info");
  EXPECT_EQ(info.exit_code, 0) << info.output;
  EXPECT_NE(info.output.find("llvmpipe"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("maxPerStageDescriptorSampledImages"), std::string::npos) << info.output;
}

// scenes/ holds exactly what tools/make_scenes.cpp generates.
std::string file_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every file the tool writes (scenes, .bin buffers, .mtl, textures/*.png) is committed byte for byte,
// and scenes/textures holds nothing the tool does not write.
TEST(Scenes, CommittedScenesAreWhatTheToolMakes) {
  const fs::path dir = test::temp_dir();
  const fs::path committed = fs::path(MOBIRT_SOURCE_DIR) / "scenes";
  ASSERT_EQ(std::system((std::string(MOBIRT_MAKE_SCENES_EXE) + " " + quoted(dir) + " > /dev/null").c_str()), 0);
  for (const char* name : {"default.gltf", "toaster.gltf", "toaster.bin", "marbles.gltf", "marbles.bin", "fish.gltf",
                           "fish.bin", "utah-toasters.mtl"}) {
    EXPECT_TRUE(fs::is_regular_file(dir / name)) << name << " is not made by the tool";
  }
  const std::string hint = " differs from the generator's output: run build/mobirt_make_scenes scenes";
  size_t files = 0;
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), dir);
    ASSERT_TRUE(fs::is_regular_file(committed / rel)) << "scenes/" << rel.string() << " is missing:" << hint;
    EXPECT_TRUE(file_bytes(e.path()) == file_bytes(committed / rel)) << "scenes/" << rel.string() << hint;
    ++files;
  }
  EXPECT_GE(files, 8u + 20u);  // the scenes above and their textures
  for (const fs::directory_entry& e : fs::directory_iterator(committed / "textures")) {
    EXPECT_TRUE(fs::is_regular_file(dir / "textures" / e.path().filename()))
        << "scenes/textures/" << e.path().filename().string() << " is not made by the tool: remove it";
  }
}

}  // namespace
}  // namespace mobirt
