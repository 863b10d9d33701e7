// Checking error messages in tests.
#pragma once

#include <exception>
#include <string>

namespace range_image_mapping::test {

// The message of what function throws, or "no exception".
template <typename Function>
std::string errorOf(Function&& function) {
  try {
    function();
  } catch (const std::exception& error) {
    return error.what();
  }
  return "no exception";
}

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

}  // namespace range_image_mapping::test
