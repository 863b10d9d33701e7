// Little-endian scalars of packets and binary files (Ouster packets, KITTI
// .bin, PLY). The formats are little-endian and so are the hosts we build for,
// so a copy is all it takes (memcpy, never a cast: fields are not aligned).
// Private to the library, shared with io (which sits above it).
#pragma once

#include <cstring>
#include <string>

namespace range_image_mapping {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "binary file io assumes a little-endian host");

template <typename T>
T readLittleEndian(const void* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

template <typename T>
void appendLittleEndian(std::string& buffer, T value) {
  buffer.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

}  // namespace range_image_mapping
