// md5 of raw bytes as lowercase hex, to compare decoded arrays with golden digests.
#pragma once

#include <openssl/evp.h>

#include <cstddef>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::test {

inline std::string md5Hex(const void* data, std::size_t size) {
  const std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> context(EVP_MD_CTX_new(),
                                                                        &EVP_MD_CTX_free);
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int digest_size = 0;
  if (!context || EVP_DigestInit_ex(context.get(), EVP_md5(), nullptr) != 1 ||
      EVP_DigestUpdate(context.get(), data, size) != 1 ||
      EVP_DigestFinal_ex(context.get(), digest, &digest_size) != 1)
    throw std::runtime_error("md5: OpenSSL EVP failed");
  static const char kHex[] = "0123456789abcdef";
  std::string hex;
  for (unsigned int i = 0; i < digest_size; ++i) {
    hex.push_back(kHex[digest[i] >> 4]);
    hex.push_back(kHex[digest[i] & 0x0F]);
  }
  return hex;
}

// The md5 of a vector's elements as they lie in memory (little-endian host).
template <typename T>
std::string md5Hex(const std::vector<T>& values) {
  return md5Hex(values.data(), values.size() * sizeof(T));
}

}  // namespace range_image_mapping::test
