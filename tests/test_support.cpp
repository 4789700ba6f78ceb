#include "test_support.h"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>

namespace mobirt::test {

std::filesystem::path shared_scenes() {
  const char* env = std::getenv("MOBIRT_SHARED_SCENES");
  std::filesystem::path path = env ? env : MOBIRT_SOURCE_DIR "/../shared/scenes";
  return std::filesystem::is_directory(path) ? path : std::filesystem::path();
}

std::filesystem::path output_path(const std::string& name) {
  std::filesystem::path dir(MOBIRT_TEST_OUTPUT_DIR);
  std::filesystem::create_directories(dir);
  return dir / name;
}

std::filesystem::path temp_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "mobirt";
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  std::filesystem::path dir = std::filesystem::temp_directory_path() / ("mobirt-test-" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

CommandResult run_mobirt(const std::string& args) {
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

}  // namespace mobirt::test
