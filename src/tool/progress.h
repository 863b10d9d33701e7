// A progress bar on one line of stderr, shared by the long-running subcommands.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace range_image_mapping::tool {

// Frames done of total, with frames per second and time left, redrawn at most
// five times a second; total <= 0 (unknown) shows the count and rate only.
// Call with done == total at the end, or finishProgress() when total is unknown.
inline void showProgress(int done, int total, std::chrono::steady_clock::time_point start) {
  static double last_drawn = -1.0;
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (done != total && elapsed - last_drawn < 0.2) return;
  last_drawn = elapsed;
  const double rate = done / std::max(elapsed, 1e-9);
  if (total <= 0) {
    std::fprintf(stderr, "\r%d frames, %.1f frames/s ", done, rate);
    return;
  }
  const int width = 30, filled = width * std::min(done, total) / total;
  std::fprintf(stderr, "\r[%.*s%*s] %d/%d frames, %.1f frames/s, %.0f s left ", filled,
               "##############################", width - filled, "", done, total, rate,
               std::max(total - done, 0) / std::max(rate, 1e-9));
  if (done == total) std::fprintf(stderr, "\n");
}

inline void finishProgress() { std::fprintf(stderr, "\n"); }

}  // namespace range_image_mapping::tool
