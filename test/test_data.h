// Where tests and benchmarks find the real sensor data (../shared/data next to
// the repository, or $RIM_DATA_DIR). The data is never copied into the repo.
#pragma once

#include <string>

namespace range_image_mapping::test {

std::string dataDirectory();
// Full path of a file below the data directory, or "" when it is absent.
std::string dataFile(const std::string& relative_path);

}  // namespace range_image_mapping::test

// Skips the current gtest with a message naming the missing file.
#define RIM_REQUIRE_DATA(variable, relative_path)                                        \
  const std::string variable = ::range_image_mapping::test::dataFile(relative_path);     \
  if (variable.empty()) {                                                                \
    GTEST_SKIP() << "sensor data not found: " << relative_path << " (looked in "         \
                 << ::range_image_mapping::test::dataDirectory()                         \
                 << "; set RIM_DATA_DIR to the shared/data folder)";                     \
  }
