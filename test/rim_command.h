// Running the built rim binary from tests: a fresh folder per test, the exit
// code and what the command printed.
#pragma once

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace range_image_mapping::test {

struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

inline std::string readText(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

class RimCommandTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    directory_ = std::filesystem::temp_directory_path() /
                 ("rim_" + std::string(test->test_suite_name()) + "_" + test->name() + "_" +
                  std::to_string(getpid()));
    std::filesystem::remove_all(directory_);
    std::filesystem::create_directories(directory_);
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  std::string path(const std::string& name) const { return (directory_ / name).string(); }

  // `environment` is prepended to the command line, e.g. "PATH=/nonexistent".
  RunResult rim(const std::string& arguments, const std::string& environment = "") const {
    const std::string out = path("stdout.txt"), err = path("stderr.txt");
    const std::string command = environment + " '" + std::string(RIM_BINARY_DIR) + "/rim' " +
                                arguments + " >'" + out + "' 2>'" + err + "'";
    const int status = std::system(command.c_str());
    RunResult result;
    result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    result.out = readText(out);
    result.err = readText(err);
    return result;
  }

  std::filesystem::path directory_;
};

}  // namespace range_image_mapping::test
