// A comma-separated command-line value ("a,b,c") as its items, empty items dropped.
#pragma once

#include <sstream>
#include <string>
#include <vector>

namespace range_image_mapping::benchmark_support {

inline std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');)
    if (!item.empty()) items.push_back(item);
  return items;
}

}  // namespace range_image_mapping::benchmark_support
