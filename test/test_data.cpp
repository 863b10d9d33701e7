#include "test_data.h"

#include <cstdlib>
#include <filesystem>

namespace range_image_mapping::test {

std::string dataDirectory() {
  if (const char* from_environment = std::getenv("RIM_DATA_DIR")) return from_environment;
  return RIM_DEFAULT_DATA_DIR;
}

std::string dataFile(const std::string& relative_path) {
  const std::filesystem::path path = std::filesystem::path(dataDirectory()) / relative_path;
  return std::filesystem::exists(path) ? path.string() : std::string();
}

}  // namespace range_image_mapping::test
