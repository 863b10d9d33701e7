// Little-endian scalars of binary files (KITTI .bin, PLY). The formats are
// little-endian and so are the hosts we build for, so a copy is all it takes.
#pragma once

#include <cstring>
#include <string>

namespace range_image_mapping::io {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "binary file io assumes a little-endian host");

template <typename T>
T readLittleEndian(const char* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

template <typename T>
void appendLittleEndian(std::string& buffer, T value) {
  buffer.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

}  // namespace range_image_mapping::io
