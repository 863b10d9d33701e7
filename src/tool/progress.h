// A progress bar on one line of stderr, shared by the long-running subcommands.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace range_image_mapping::tool {

// What the line shows, and the last call, which may not have been drawn.
struct ProgressLine {
  double last_drawn_s = -1.0;
  int done = 0, total = 0;
  double elapsed_s = 0.0;
  bool drawn = true;  // the last call was drawn
};

inline ProgressLine& progressLine() {
  static ProgressLine line;
  return line;
}

inline void drawProgress(ProgressLine& line) {
  line.last_drawn_s = line.elapsed_s;
  line.drawn = true;
  const double rate = line.done / std::max(line.elapsed_s, 1e-9);
  if (line.total <= 0) {
    std::fprintf(stderr, "\r%d frames, %.1f frames/s ", line.done, rate);
    return;
  }
  const int width = 30, filled = width * std::min(line.done, line.total) / line.total;
  std::fprintf(stderr, "\r[%.*s%*s] %d/%d frames, %.1f frames/s, %.0f s left ", filled,
               "##############################", width - filled, "", line.done, line.total, rate,
               std::max(line.total - line.done, 0) / std::max(rate, 1e-9));
  if (line.done == line.total) std::fprintf(stderr, "\n");
}

// Frames done of total, with frames per second and time left, redrawn at most
// five times a second; total <= 0 (unknown) shows the count and rate only.
// Call with done == total at the end, or finishProgress() when total is unknown.
inline void showProgress(int done, int total, std::chrono::steady_clock::time_point start) {
  ProgressLine& line = progressLine();
  line.done = done;
  line.total = total;
  line.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  line.drawn = false;
  if (done != total && line.elapsed_s - line.last_drawn_s < 0.2) return;
  drawProgress(line);
}

// Ends the line, first drawing the last count if it was not drawn.
inline void finishProgress() {
  ProgressLine& line = progressLine();
  if (!line.drawn && line.done != line.total) drawProgress(line);
  std::fprintf(stderr, "\n");
}

}  // namespace range_image_mapping::tool
