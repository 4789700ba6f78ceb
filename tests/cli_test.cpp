// The command line as a user meets it: bad input ends with one line naming the file and the
// problem, exit code 2 and no output file; the project's scenes are what its tool generates.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/image.h"
#include "test_support.h"

namespace mobirt {
namespace {

namespace fs = std::filesystem;

using test::CommandResult;
CommandResult run(const std::string& args) { return test::run_mobirt(args); }

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
  expect_refused("render " + scene + " --intersect plucker", out, "expected one of mt, watertight");
  expect_refused("render " + scene + " --precision lowp", out, "expected one of highp, mediump");
  expect_refused("render " + scene + " --offset huge", out, "expected one of fixed, scaled, normal-ulp");
  expect_refused("render " + scene + " --colour 10", out, "expected one of 8, 16");
  expect_refused("render " + scene + " --build sah", out, "expected one of fast, quality");
  expect_refused("render " + scene + " --pin-threads maybe", out, "expected one of on, off");
  expect_refused("render " + scene + " --gpu-timestamps sometimes", out, "expected one of auto, on, off");
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

// --help comes from the option table: every command lists the shared render settings it takes,
// with their values, beside its own options.
TEST(Cli, HelpListsTheSharedSettings) {
  const std::vector<std::string> frame_settings = {"--stack N",        "--max-steps N", "--cpu-walks N", "--bins N",
                                                   "--leaf-size N",    "--cluster-refs N", "--empty-bonus B",
                                                   "--max-depth N", "--offset MODE", "--epsilon E",
                                                   "--intersect TEST", "--precision P", "--colour 8|16",
                                                   "--min-weight W", "--general", "--device D", "--validation"};
  const std::vector<std::string> view_settings = {"--size WxH", "--depth N", "--no-shadows", "--always-rebuild",
                                                  "--light SPEC", "--camera SPEC", "--background R,G,B",
                                                  "--time T", "--mtl FILE"};
  for (const char* command : {"render", "accuracy", "bench"}) {
    SCOPED_TRACE(command);
    const CommandResult r = run(std::string(command) + " --help");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(r.output.rfind(std::string("Usage: mobirt ") + command, 0), 0u) << r.output;
    EXPECT_NE(r.output.find("Render options:"), std::string::npos) << r.output;
    for (const std::string& s : frame_settings) EXPECT_NE(r.output.find("  " + s + " "), std::string::npos) << s;
    // Past the 26-character column: its description on the next line.
    EXPECT_NE(r.output.find("  --gpu-timestamps auto|on|off\n"), std::string::npos) << r.output;
    for (const std::string& s : view_settings) {
      // bench sets each cell's view itself; its --size is for scenes given on the command line.
      if (std::string(command) == "bench" && s != "--size WxH") {
        EXPECT_EQ(r.output.find("  " + s + " "), std::string::npos) << s;
      } else {
        EXPECT_NE(r.output.find("  " + s + " "), std::string::npos) << s;
      }
    }
  }
  const CommandResult render = run("render --help");
  EXPECT_NE(render.output.find("  -o, --output FILE       output image (required)\n"), std::string::npos)
      << render.output;
  EXPECT_NE(render.output.find("  --backend gles|vulkan   "), std::string::npos) << render.output;
}

// A bad value, an unknown option and an option without its value: one line naming the option and
// where the options are described, exit 2, in every command, before any work is done.
TEST(Cli, BadOptionsGiveTheDocumentedMessage) {
  const std::string scene = MOBIRT_SOURCE_DIR "/scenes/default.gltf";
  struct Case {
    std::string args, message;
  };
  const Case cases[] = {
      {"render " + scene + " --stack 99 -o x.png", "--stack 99: expected an integer in [0, 32] (see mobirt --help)"},
      {"render " + scene + " --depth x -o x.png", "--depth x: expected an integer in [0, 64] (see mobirt --help)"},
      {"render " + scene + " --intersect plucker -o x.png",
       "--intersect plucker: expected one of mt, watertight (see mobirt --help)"},
      {"render " + scene + " --frobnicate -o x.png", "render: unknown option --frobnicate (see mobirt --help)"},
      {"render " + scene + " -o x.png --bins", "--bins needs a value (see mobirt --help)"},
      {"render " + scene + " " + scene + " -o x.png", "render: more than one scene given"},
      {"accuracy " + scene + " --max-steps 0",
       "--max-steps 0: expected an integer in [1, 16777216] (see mobirt accuracy --help)"},
      {"accuracy " + scene + " --frobnicate", "accuracy: unknown option --frobnicate (see mobirt accuracy --help)"},
      {"accuracy " + scene + " --size 10", "--size 10: expected WxH with 1 <= W, H <= 16384, e.g. 400x240 "
                                           "(see mobirt accuracy --help)"},
      {"bench --bins 1", "--bins 1: expected an integer in [2, 1024] (see mobirt bench --help)"},
      {"bench --colour 10", "--colour 10: expected one of 8, 16 (see mobirt bench --help)"},
      {"bench --frobnicate", "bench: unknown option --frobnicate (see mobirt bench --help)"},
      {"bench --depth 1", "bench: unknown option --depth (see mobirt bench --help)"},
      {"bench --frames", "--frames needs a value (see mobirt bench --help)"},
      {"info --frobnicate", "info: unknown option --frobnicate (see mobirt --help)"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.args);
    const CommandResult r = run(c.args);
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_EQ(r.output.rfind("mobirt: error: " + c.message, 0), 0u) << r.output;
  }
}

// A negative number is a value, not an option.
TEST(Cli, NegativeValuesAreValues) {
  const fs::path dir = test::temp_dir();
  const CommandResult r = run("render " MOBIRT_SOURCE_DIR "/scenes/default.gltf --size 32x20 --max-depth -1 "
                              "--time -0.5 -o " + quoted(dir / "a.png"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir / "a.png"));
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

// Outputs are written whole or not at all (issue 8). Every file of a folder an interrupted or
// failed --frames render leaves: a complete, readable image of the requested size, and no
// temporary file beside them.
void expect_only_complete_frames(const fs::path& dir, int width, int height, size_t at_least) {
  size_t frames = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find(".tmp"), std::string::npos) << "temporary file left: " << name;
    if (!entry.is_regular_file() || entry.path().extension() != ".png") continue;
    SCOPED_TRACE(name);
    try {
      const Image image = read_image(entry.path().string());
      EXPECT_EQ(image.width, width);
      EXPECT_EQ(image.height, height);
      ++frames;
    } catch (const Error& e) {
      ADD_FAILURE() << "not a complete image: " << e.what();
    }
  }
  EXPECT_GE(frames, at_least);
}

// SIGINT part way through a long --frames render: the process stops (exit 130) and leaves only
// complete PNGs. The signal is sent once at least one frame exists, plus about 1.5 s.
TEST(Cli, InterruptedFramesLeaveOnlyCompleteImages) {
  const fs::path dir = test::temp_dir();
  const std::string out = (dir / "f_%04d.png").string();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int devnull = ::open("/dev/null", O_WRONLY);
    if (devnull >= 0) {
      dup2(devnull, 1);
      dup2(devnull, 2);
    }
    execl(MOBIRT_EXE, MOBIRT_EXE, "render", MOBIRT_SOURCE_DIR "/scenes/toaster.gltf", "--frames", "0:200", "-o",
          out.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  auto any_frame = [&] {
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (entry.path().filename().string().rfind("f_", 0) == 0) return true;
    }
    return false;
  };
  int status = 0;
  bool exited = false;
  for (int i = 0; i < 1200 && !any_frame(); ++i) {  // up to 2 minutes (slow sanitizer builds)
    if (waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    usleep(100000);
  }
  ASSERT_FALSE(exited) << "mobirt ended before writing a frame, status " << status;
  usleep(1500000);
  ASSERT_EQ(kill(pid, SIGINT), 0);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  EXPECT_EQ(WEXITSTATUS(status), 130);
  expect_only_complete_frames(dir, 400, 240, 1);
}

// An error part way through a sequence (frame 2's name is taken by a folder, so its rename fails):
// exit 2 with one line naming that frame; frames 0 and 1 are complete; no temporary file remains.
TEST(Cli, ErrorMidSequenceLeavesOnlyCompleteImages) {
  const fs::path dir = test::temp_dir();
  fs::create_directory(dir / "f_0002.png");
  const CommandResult r = run("render " MOBIRT_SOURCE_DIR "/scenes/default.gltf --size 64x40 --frames 0:4 -o " +
                              quoted(dir / "f_%04d.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("f_0002.png"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_TRUE(fs::is_regular_file(dir / "f_0000.png"));
  EXPECT_TRUE(fs::is_regular_file(dir / "f_0001.png"));
  EXPECT_FALSE(fs::exists(dir / "f_0003.png"));
  expect_only_complete_frames(dir, 64, 40, 2);
}

}  // namespace
}  // namespace mobirt
