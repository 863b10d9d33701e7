// Wall and process CPU time of calls, and the statistics the benchmarks
// print of them (shared so that their columns mean the same).
#pragma once

#include "machine_info.h"

#include <algorithm>
#include <chrono>
#include <numeric>
#include <vector>

namespace range_image_mapping::benchmark_support {

inline double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Wall and CPU time since construction.
struct Timer {
  std::chrono::steady_clock::time_point wall_start = std::chrono::steady_clock::now();
  double cpu_start = processCpuSeconds();
  double wall() const { return secondsSince(wall_start); }
  double cpu() const { return processCpuSeconds() - cpu_start; }
};

inline double mean(const std::vector<double>& values) {
  return values.empty() ? 0.0 : std::accumulate(values.begin(), values.end(), 0.0) / double(values.size());
}

// The value below which `share` of the values lie (0.5: the median); 0 for none.
inline double percentile(std::vector<double> values, double share) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  return values[std::min(values.size() - 1, std::size_t(share * double(values.size())))];
}

}  // namespace range_image_mapping::benchmark_support
