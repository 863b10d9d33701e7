// Fresh memory of large arrays (a full mesh, tens of MB) costs one page fault
// per 4 KB on first touch, more than the writes themselves; advising Linux
// to back the array with 2 MB pages (transparent huge pages, "madvise" mode,
// the usual default) makes that one fault per 2 MB. Only the 2 MB-aligned
// part of the range is advised: the rest, and memory already touched, is
// unaffected. Elsewhere, or when the kernel declines, nothing happens.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace range_image_mapping::mapping {

// Call after allocating and before first writing the array.
inline void adviseHugePages(const void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr uintptr_t kHugePage = uintptr_t(2) << 20;
  if (bytes < 2 * kHugePage) return;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHugePage - 1) & ~(kHugePage - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHugePage - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)data;
  (void)bytes;
#endif
}

// Grows `values` to `count` elements, advised as above before the new
// elements are constructed (a value-initialising resize writes them).
template <typename T>
void resizeOnHugePages(std::vector<T>& values, std::size_t count) {
  values.reserve(count);
  adviseHugePages(values.data(), count * sizeof(T));
  values.resize(count);
}

}  // namespace range_image_mapping::mapping
