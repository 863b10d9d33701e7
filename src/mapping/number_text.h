// Numbers in mapping error messages, as the user wrote them (no fixed digits).
#pragma once

#include <sstream>
#include <string>

namespace range_image_mapping::mapping {

inline std::string numberText(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

}  // namespace range_image_mapping::mapping
