// Points and normals of a range image, computed in the image domain at any
// pyramid level (a strided view of the full image; no copies of the ranges).
#pragma once

#include "range_image_mapping/range_image.h"

#include <vector>

namespace range_image_mapping {

enum class NormalMethod {
  kCrossProduct,  // neighbouring pixels (right/left and up/down), Behley & Stachniss style
  kCovariance,    // smallest eigenvector of a small window's covariance
};

struct NormalMapOptions {
  NormalMethod method = NormalMethod::kCrossProduct;
  int window_radius = 1;  // kCovariance: (2r+1)^2 pixels of the level
  // A neighbour whose range differs from the pixel's by more than this
  // fraction of the pixel's range, per full-resolution pixel between them
  // (so s times more at level s), is across a depth discontinuity: the pixel
  // sits on an edge and gets no normal.
  float max_range_jump_ratio = 0.1f;
  // Cross-product normals at full resolution, > 0: a pixel gets a normal
  // only where it lies within this of the chord between its two neighbours
  // on each axis (on one plane the beams of one azimuth meet it in a line,
  // and a ring is straight across a few columns), both neighbours present.
  // The rows' neighbours then count whatever their range jump: a sparse
  // sensor's ground rings jump by far more than max_range_jump_ratio, while
  // a far wall's row against the roof behind it passes the ratio and leaves
  // the line. 0: the range-jump test alone (one-sided tangents allowed).
  float max_chord_offset_m = 0.0f;
};

// Level `stride` of an image: pixel (i, j) is full-resolution pixel
// (stride * i, stride * j). Invalid points and normals are NaN: a pixel
// without a return has neither; a pixel on a depth edge or without enough
// neighbours has its point but no normal. Normals are unit length and face
// the sensor. Columns wrap around (the image is a cylinder); rows do not.
struct VertexNormalMap {
  int rows = 0, columns = 0, stride = 1;
  std::vector<Eigen::Vector3f> points;   // lidar frame
  std::vector<Eigen::Vector3f> normals;
  const Eigen::Vector3f& point(int row, int column) const { return points[std::size_t(row) * columns + column]; }
  const Eigen::Vector3f& normal(int row, int column) const { return normals[std::size_t(row) * columns + column]; }
};

// Nearest pixel of a level to a full-resolution pixel (level pixel (i, j) is
// full pixel (s i, s j)): columns wrap (column W is column 0), rows clamp.
// Called for every pair of every ICP iteration: strides that are powers of
// two (the usual pyramid) shift instead of dividing.
inline std::size_t levelPixelIndex(const VertexNormalMap& level, const ProjectedPixel& pixel) {
  const int s = level.stride;
  int row = pixel.row + s / 2, column = pixel.column + s / 2;
  if ((s & (s - 1)) == 0) {
    const int shift = __builtin_ctz(unsigned(s));
    row >>= shift;
    column >>= shift;
  } else {
    row /= s;
    column /= s;
  }
  if (row >= level.rows) row = level.rows - 1;
  if (column >= level.columns) column = 0;
  return std::size_t(row) * level.columns + column;
}

// levelPixelIndex of one level tabulated for a full_rows x full_columns
// image, as the sum of a part per full-resolution row (its level row's first
// pixel) and one per column (its level column): the loops that file every
// point of a scan add two looked-up integers instead of shifting and clamping.
struct LevelPixelTables {
  std::vector<int> row_start, column;
  void build(const VertexNormalMap& level, int full_rows, int full_columns) {
    row_start.resize(std::size_t(full_rows));
    column.resize(std::size_t(full_columns));
    for (int r = 0; r < full_rows; ++r) row_start[r] = int(levelPixelIndex(level, ProjectedPixel{0, r}));
    for (int c = 0; c < full_columns; ++c) column[c] = int(levelPixelIndex(level, ProjectedPixel{c, 0}));
  }
  // For a pixel inside the full-resolution image.
  std::size_t index(const ProjectedPixel& pixel) const {
    return std::size_t(row_start[std::size_t(pixel.row)] + column[std::size_t(pixel.column)]);
  }
};

// Reuses out's buffers. The image must be staggered; throws
// std::invalid_argument for a missing model, wrong sizes, a destaggered image,
// stride < 1 or bad options. Parallel over rows (TBB).
void computeVertexNormalMap(const RangeImage& image, int stride, const NormalMapOptions& options,
                            VertexNormalMap& out);

}  // namespace range_image_mapping
