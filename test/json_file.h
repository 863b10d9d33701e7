// A JSON file a command wrote (report.json), parsed; a test failure naming the
// file when it is no valid JSON.
#pragma once

#include "rim_command.h"

#include <gtest/gtest.h>
#include <json/json.h>

#include <sstream>
#include <string>

namespace range_image_mapping::test {

inline Json::Value readJsonFile(const std::string& path) {
  Json::Value root;
  std::istringstream text(readText(path));
  std::string errors;
  EXPECT_TRUE(Json::parseFromStream(Json::CharReaderBuilder(), text, &root, &errors)) << path << ": " << errors;
  return root;
}

}  // namespace range_image_mapping::test
