// Grey PNG images (libpng): 8 and 16 bit, and range images made viewable.
#pragma once

#include "range_image_mapping/range_image.h"

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// A PNG that cannot be written or read; what() names the file and the problem.
class PngError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Row-major grey pixels; the size of pixels must be width * height.
void writeGrey8Png(const std::string& path, int width, int height,
                   const std::vector<uint8_t>& pixels);
void writeGrey16Png(const std::string& path, int width, int height,
                    const std::vector<uint16_t>& pixels);

// A grey PNG read back (8 or 16 bit; other formats throw PngError).
struct GreyPng {
  int width = 0;
  int height = 0;
  int bit_depth = 0;             // 8 or 16
  std::vector<uint16_t> pixels;  // row-major, values as stored
};
GreyPng readGreyPng(const std::string& path);

// How writeRangeImagePng turns ranges into grey levels.
struct RangePngOptions {
  float near_m = 1.0f;   // this range and nearer: 255 (white)
  float far_m = 100.0f;  // this range and farther: 1 (darkest grey that is not "no return")
  int row_repeat = 1;    // each image row written this many times (flat sensors are hard to see)
};

// Writes the image destaggered (as the scene looks), 8-bit grey: no return = 0
// (black); valid ranges map to 255 .. 1 with the logarithm of the range between
// near_m and far_m, so near is bright and detail at short range is not crushed:
//   grey = 1 + round(254 * (1 - log(r / near) / log(far / near))), clamped.
void writeRangeImagePng(const std::string& path, const RangeImage& image,
                        const RangePngOptions& options = {});

}  // namespace range_image_mapping::io
