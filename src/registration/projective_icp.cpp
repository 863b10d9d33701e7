#include "range_image_mapping/registration/projective_icp.h"

#include "range_image_mapping/lidar_intrinsics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::registration {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// Source points go through Pi in chunks of this size, on the stack of the
// thread that owns them.
constexpr std::size_t kProjectionChunk = 256;
// Float lanes of the per-chunk sums: two SSE (one AVX) registers.
constexpr std::size_t kLanes = 8;

// One chunk's points as a structure of arrays (rows: the point-to-plane
// jacobian [p x n, n], the weight, the residual), zero-padded to whole
// lanes: every sum over the chunk is a loop the compiler vectorises. A point
// without a pair has zero rows: it adds nothing to the sums.
struct ChunkPairs {
  enum Row { kWeight = 6, kResidual = 7, kRows = 8 };
  alignas(32) float rows[kRows][kProjectionChunk];
  std::size_t count = 0;    // points in the chunk
  std::size_t inliers = 0;  // of them with a pair
  double area_weights = 0.0;  // sum of the pairs' area weights

  // Zeroes the rows up to whole lanes; returns the padded length.
  std::size_t pad() {
    const std::size_t padded = (count + kLanes - 1) / kLanes * kLanes;
    for (auto& row : rows) std::fill(row + count, row + padded, 0.0f);
    return padded;
  }
};

// The 21 hessian entries (upper triangle, row by row), 6 gradient entries and
// the squared residuals of one padded chunk: sum_k a[k] b[k] * c[k] in kLanes
// float partial sums each, at most kProjectionChunk / kLanes terms, so float
// stays exact to about 1e-6 of the chunk's sum, far below what the solve
// resolves (the chunks are then summed in double). All 28 in one pass over
// the chunk, each row read once per lane group; every lane still adds its
// terms in the order of k. Cloned for AVX2 and AVX-512: the eight lanes in
// one register instead of two, the same sums (no FMA).
constexpr std::size_t kChunkSums = 28;
RANGE_IMAGE_MAPPING_SIMD_CLONES
void chunkSums(const float (*rows)[kProjectionChunk], std::size_t padded, double* sums) {
  // kLanes floats as one value (GCC's vector extension): element-wise float
  // arithmetic, one register with AVX2, two without.
  using Lanes = float __attribute__((vector_size(kLanes * sizeof(float))));
  Lanes partial[kChunkSums] = {};
  for (std::size_t k = 0; k < padded; k += kLanes) {
    Lanes jacobian[6], weight, residual;
    for (int i = 0; i < 6; ++i) std::memcpy(&jacobian[i], rows[i] + k, sizeof(Lanes));
    std::memcpy(&weight, rows[ChunkPairs::kWeight] + k, sizeof weight);
    std::memcpy(&residual, rows[ChunkPairs::kResidual] + k, sizeof residual);
    std::size_t out = 0;
    for (int i = 0; i < 6; ++i)
      for (int j = i; j < 6; ++j) partial[out++] += jacobian[i] * jacobian[j] * weight;
    for (int i = 0; i < 6; ++i) partial[out++] += jacobian[i] * residual * weight;
    partial[out] += residual * residual;
  }
  for (std::size_t out = 0; out < kChunkSums; ++out) {
    double total = 0.0;
    for (std::size_t l = 0; l < kLanes; ++l) total += partial[out][l];
    sums[out] = total;
  }
}

// The six coordinate arrays of a chunk: x, y, z of the points, then of
// their normals (SourceLevel's order).
constexpr int kCoordinates = 6;
using ChunkCoordinates = float[kCoordinates][kProjectionChunk];
constexpr int kTransformFloats = ColumnMotion::SizeAtCompileTime;

// Source points and normals into the target frame, [R | t] p and R n, with
// R and t entry j of a transform at transforms[j * stride + i] (column-major
// [R | t]): i is the point's full-resolution column where per_column (the
// target_from_source transform composed with the column's deskew motion,
// gathered per point), else 0 (one transform for all). Each coordinate sums
// its three products left to right, then adds the translation. Plain arrays
// over separate coordinates so that it vectorises; cloned for AVX2 and
// AVX-512 (no fused multiply-adds: every product rounds).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void moveChunk(const float* const* source, std::size_t first, const int* columns, std::size_t count,
               const float* transforms, std::size_t stride, bool per_column,
               float (*__restrict moved)[kProjectionChunk]) {
  const float *x = source[0] + first, *y = source[1] + first, *z = source[2] + first;
  const float *nx = source[3] + first, *ny = source[4] + first, *nz = source[5] + first;
  if (per_column) {
    for (std::size_t k = 0; k < count; ++k) {
      const int c = columns[k];
      for (int axis = 0; axis < 3; ++axis) {
        const float r0 = transforms[std::size_t(axis) * stride + c];
        const float r1 = transforms[std::size_t(3 + axis) * stride + c];
        const float r2 = transforms[std::size_t(6 + axis) * stride + c];
        const float t = transforms[std::size_t(9 + axis) * stride + c];
        moved[axis][k] = r0 * x[k] + r1 * y[k] + r2 * z[k] + t;
        moved[3 + axis][k] = r0 * nx[k] + r1 * ny[k] + r2 * nz[k];
      }
    }
  } else {
    float transform[kTransformFloats];
    for (int j = 0; j < kTransformFloats; ++j) transform[j] = transforms[j];
    for (std::size_t k = 0; k < count; ++k)
      for (int axis = 0; axis < 3; ++axis) {
        moved[axis][k] = transform[axis] * x[k] + transform[3 + axis] * y[k] + transform[6 + axis] * z[k] +
                         transform[9 + axis];
        moved[3 + axis][k] = transform[axis] * nx[k] + transform[3 + axis] * ny[k] + transform[6 + axis] * nz[k];
      }
  }
}

// A target level as plain arrays. levelPixelIndex is the sum of a row part
// and a column part (pixel (0, r) and pixel (c, 0)): both are tabulated per
// full-resolution row and column.
struct TargetArrays {
  const float* points;   // xyz triples
  const float* normals;  // xyz triples, NaN where there is no normal
  const int* row_start;  // full-resolution row -> its level row's first pixel
  const int* column;     // full-resolution column -> level column
};

// Association (paper eq. 5) of one chunk and its point-to-plane rows, branch
// free over plain arrays so that it vectorises: the target look-ups become
// gathers, a rejected point gets zero rows (paired is an integer mask; every
// comparison is false for a NaN target normal). A source point without a
// normal has a zero one: m.n >= cos |m|^2 holds for it. moved holds the
// moved points and normals (moveChunk). The rows must not overlap the inputs
// (restrict: gathers are not vectorised past stores that may alias them).
// Cloned for AVX2 and AVX-512. Returns the number of pairs.
RANGE_IMAGE_MAPPING_SIMD_CLONES
std::size_t pairRows(const ChunkCoordinates& moved, const ProjectedPixel* pixels, const uint8_t* hits,
                     std::size_t count, const TargetArrays& target, float max_distance_squared, float min_cosine,
                     float (*__restrict rows)[kProjectionChunk]) {
  std::size_t inliers = 0;
  for (std::size_t k = 0; k < count; ++k) {
    const int hit = hits[k];
    // Pixel 0 where there is no hit; 32-bit indices, as a gather takes them.
    const int t = 3 * (target.row_start[pixels[k].row & -hit] + target.column[pixels[k].column & -hit]);
    const float p[3] = {moved[0][k], moved[1][k], moved[2][k]};
    const float m[3] = {moved[3][k], moved[4][k], moved[5][k]};
    const float nx = target.normals[t], ny = target.normals[t + 1], nz = target.normals[t + 2];
    const float dx = p[0] - target.points[t], dy = p[1] - target.points[t + 1], dz = p[2] - target.points[t + 2];
    const int paired = hit & int(dx * dx + dy * dy + dz * dz <= max_distance_squared) &
                       int(m[0] * nx + m[1] * ny + m[2] * nz >= min_cosine * (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]));
    rows[0][k] = zeroUnless(p[1] * nz - p[2] * ny, paired);  // p x n
    rows[1][k] = zeroUnless(p[2] * nx - p[0] * nz, paired);
    rows[2][k] = zeroUnless(p[0] * ny - p[1] * nx, paired);
    rows[3][k] = zeroUnless(nx, paired);
    rows[4][k] = zeroUnless(ny, paired);
    rows[5][k] = zeroUnless(nz, paired);
    rows[ChunkPairs::kResidual][k] = zeroUnless(nx * dx + ny * dy + nz * dz, paired);
    inliers += std::size_t(paired);
  }
  return inliers;
}

// The area weights (range^2 up to the cap, over the cap's square) of a
// chunk's moved points: each pair's weight multiplied by its point's, and
// the point's in paired_areas where it has a pair (a non-zero normal row),
// else zero. Cloned for AVX2 and AVX-512.
RANGE_IMAGE_MAPPING_SIMD_CLONES
void areaWeights(const ChunkCoordinates& moved, float (*__restrict rows)[kProjectionChunk], std::size_t count,
                 float max_range_squared, float* __restrict paired_areas) {
  float* weights = rows[ChunkPairs::kWeight];
  for (std::size_t k = 0; k < count; ++k) {
    // Summed as Eigen's squaredNorm sums three terms: x^2 + (y^2 + z^2).
    const float x = moved[0][k], y = moved[1][k], z = moved[2][k];
    const float area = std::min(x * x + (y * y + z * z), max_range_squared) / max_range_squared;
    weights[k] *= area;
    const int paired = int(rows[3][k] != 0.0f) | int(rows[4][k] != 0.0f) | int(rows[5][k] != 0.0f);
    paired_areas[k] = zeroUnless(area, paired);
  }
}

// Normal equations of one Gauss-Newton step, summed per thread and joined.
// The hessian is kept as its 21 upper-triangle entries (row by row).
struct NormalEquations {
  std::array<double, 21> hessian_upper{};
  Vector6d gradient = Vector6d::Zero();
  double squared_residuals = 0.0;
  double area_weights = 0.0;
  std::size_t inliers = 0;

  void add(const NormalEquations& other) {
    for (std::size_t k = 0; k < hessian_upper.size(); ++k) hessian_upper[k] += other.hessian_upper[k];
    gradient += other.gradient;
    squared_residuals += other.squared_residuals;
    area_weights += other.area_weights;
    inliers += other.inliers;
  }
  // J^T W J += sum_k w_k J_k J_k^T; J^T W r += sum_k w_k r_k J_k (paper eq. 6).
  void add(ChunkPairs& pairs) {
    if (pairs.inliers == 0) return;
    double sums[kChunkSums];
    chunkSums(pairs.rows, pairs.pad(), sums);
    for (std::size_t k = 0; k < hessian_upper.size(); ++k) hessian_upper[k] += sums[k];
    for (int i = 0; i < 6; ++i) gradient(i) += sums[hessian_upper.size() + i];
    squared_residuals += sums[kChunkSums - 1];
    area_weights += pairs.area_weights;
    inliers += pairs.inliers;
  }
  Matrix6d hessian() const {
    Matrix6d full;
    std::size_t k = 0;
    for (int i = 0; i < 6; ++i)
      for (int j = i; j < 6; ++j) full(i, j) = full(j, i) = hessian_upper[k++];
    return full;
  }
};

// Robust weight with the kernel's constants worked out once per iteration
// rather than per pair.
class KernelWeight {
 public:
  explicit KernelWeight(const RobustKernel& kernel)
      : type_(kernel.type),
        alpha_(kernel.alpha),
        inverse_scale_squared_(1.0 / (kernel.scale_m * kernel.scale_m)),
        inverse_alpha_distance_(1.0 / std::abs(kernel.alpha - 2.0)) {}
  double operator()(double residual_m) const {
    const double x2 = residual_m * residual_m * inverse_scale_squared_;
    if (type_ == RobustKernel::Type::kPseudoHuber) return 1.0 / std::sqrt(1.0 + x2);
    if (alpha_ == 2.0) return 1.0;
    if (alpha_ == 0.0) return 2.0 / (x2 + 2.0);
    return std::pow(x2 * inverse_alpha_distance_ + 1.0, alpha_ / 2.0 - 1.0);
  }
  // Many at once; the pseudo-Huber kernel (the default) in float, vectorised.
  void weights(const float* residuals_m, std::size_t count, float* out) const {
    if (type_ == RobustKernel::Type::kPseudoHuber) {
      const float inverse_scale_squared = float(inverse_scale_squared_);
      for (std::size_t k = 0; k < count; ++k)
        out[k] = 1.0f / std::sqrt(1.0f + residuals_m[k] * residuals_m[k] * inverse_scale_squared);
      return;
    }
    for (std::size_t k = 0; k < count; ++k) out[k] = float((*this)(residuals_m[k]));
  }

 private:
  RobustKernel::Type type_;
  double alpha_, inverse_scale_squared_, inverse_alpha_distance_;
};

// The area weight's cap, lowered on a sensor with sparse rows (median beam
// spacing d) to kAreaWeightSpacing / d^2: farther, a pixel's pair rests on a
// plane fitted across rows metres apart (a ring's spacing on the ground
// grows as range^2 d), and weighting such pairs by range^2 lets them hold
// roll and pitch, so that a VLP-16 or HDL-32E follows only a fraction of
// the body's sway (issue 14). The constant is measured: the HDL-32E
// (1.33 deg) needs about 11 m or less, the OS-0-128 (0.7 deg) indoors
// loses accuracy below 25 m; HDL-64E, OS-1-128, Pandar64 and VLP-32C keep
// the 25 m default.
constexpr double kAreaWeightSpacing_m_rad2 = 0.0045;

}  // namespace

bool sparseRows(const LidarModel& model) {
  return model.intrinsics().medianRowSpacingRad() >= M_PI / 180.0;
}

NormalMapOptions normalsFor(const RegistrationOptions& options, const LidarModel& model) {
  NormalMapOptions normals = options.normals;
  if (sparseRows(model)) normals.max_chord_offset_m = float(options.sparse_rows_chord_offset_m);
  return normals;
}

double areaWeightRange(const RegistrationOptions& options, const LidarModel& model) {
  const double max_range_m = options.area_weight_max_range_m;
  if (!(max_range_m > 0.0)) return 0.0;
  const double d = model.intrinsics().medianRowSpacingRad();
  return d > 0.0 ? std::min(max_range_m, kAreaWeightSpacing_m_rad2 / (d * d)) : max_range_m;
}

namespace {

// Pairs of one iteration (paper eq. 5-6) and their point-to-plane normal
// equations, in one parallel pass over the source points (moved by the
// transforms as moveChunk moves them).
NormalEquations accumulate(const std::array<const float*, kCoordinates>& source, const std::vector<int>& columns,
                           const float* transforms, std::size_t transform_stride, bool per_column,
                           const LidarModel& target_model, const TargetArrays& target_arrays,
                           const RegistrationOptions& options, double area_weight_range_m, double gate_m) {
  const float max_distance_squared = float(gate_m * gate_m);
  const float min_cosine = float(options.min_normal_cosine);
  const KernelWeight weight_of(options.kernel);
  const bool area_weighted = area_weight_range_m > 0.0;
  const float max_range_squared = float(area_weight_range_m * area_weight_range_m);

  // Deterministic: the same blocks summed in the same order on every run and
  // thread count, so rim run and the nodelets give the same poses to the bit.
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, columns.size(), 2048), NormalEquations{},
      [&](const tbb::blocked_range<std::size_t>& block, NormalEquations sum) {
        alignas(32) ChunkCoordinates moved;
        std::array<ProjectedPixel, kProjectionChunk> pixels;
        std::array<uint8_t, kProjectionChunk> hits;
        ChunkPairs pairs;
        for (std::size_t first = block.begin(); first < block.end(); first += kProjectionChunk) {
          const std::size_t count = std::min(kProjectionChunk, block.end() - first);
          moveChunk(source.data(), first, &columns[first], count, transforms, transform_stride, per_column, moved);
          target_model.projectMany(moved[0], moved[1], moved[2], count, pixels.data(), hits.data());
          // Association and rows, then the weights' square roots and the sums.
          pairs.count = count;
          pairs.inliers = pairRows(moved, pixels.data(), hits.data(), count, target_arrays, max_distance_squared,
                                   min_cosine, pairs.rows);
          weight_of.weights(pairs.rows[ChunkPairs::kResidual], pairs.count, pairs.rows[ChunkPairs::kWeight]);
          if (area_weighted) {
            // Each pair weighted by the surface its pixel covers (range^2,
            // relative to the cap): a range image samples near surfaces
            // densely, and a near object (a truck alongside, the ground
            // rings) would otherwise outvote the far, static world.
            // The pairs' areas (zero for a point without a pair) summed
            // in order, in double.
            alignas(32) float paired_areas[kProjectionChunk];
            areaWeights(moved, pairs.rows, count, max_range_squared, paired_areas);
            pairs.area_weights = 0.0;
            for (std::size_t k = 0; k < count; ++k) pairs.area_weights += paired_areas[k];
          } else {
            pairs.area_weights = double(pairs.inliers);
          }
          sum.add(pairs);
        }
        return sum;
      },
      [](NormalEquations a, const NormalEquations& b) {
        a.add(b);
        return a;
      });
}

// Solves H delta = -g on the well-constrained directions only: directions the
// pairs do not constrain (a single plane, a corridor) keep their value
// instead of taking a step made of rounding noise.
Vector6d solveConstrained(const Matrix6d& hessian, const Vector6d& gradient) {
  Eigen::SelfAdjointEigenSolver<Matrix6d> solver(hessian);
  const Vector6d eigenvalues = solver.eigenvalues();
  const double floor = 1e-9 * eigenvalues.maxCoeff();
  Vector6d delta = Vector6d::Zero();
  for (int k = 0; k < 6; ++k) {
    if (!(eigenvalues(k) > floor) || eigenvalues(k) <= 0.0) continue;
    const Vector6d direction = solver.eigenvectors().col(k);
    delta -= direction * (direction.dot(gradient) / eigenvalues(k));
  }
  return delta;
}

double conditionNumber(const Matrix6d& hessian) {
  const Vector6d eigenvalues = Eigen::SelfAdjointEigenSolver<Matrix6d>(hessian, Eigen::EigenvaluesOnly).eigenvalues();
  if (!(eigenvalues(0) > 0.0)) return std::numeric_limits<double>::infinity();
  return eigenvalues(5) / eigenvalues(0);
}

// Left update T <- Exp(delta) T with the exact rotation exponential and the
// translation added in the target frame.
Eigen::Isometry3d applyUpdate(const Vector6d& delta, const Eigen::Isometry3d& pose) {
  Eigen::Isometry3d update = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d rotation = delta.head<3>();
  const double angle = rotation.norm();
  if (angle > 0.0) update.linear() = Eigen::AngleAxisd(angle, rotation / angle).toRotationMatrix();
  update.translation() = delta.tail<3>();
  Eigen::Isometry3d result = update * pose;
  // Keep the rotation orthonormal over many small updates.
  result.linear() = Eigen::Quaterniond(result.linear()).normalized().toRotationMatrix();
  return result;
}

void validateOptions(const RegistrationOptions& options) {
  const auto fail = [](const std::string& what) { throw std::invalid_argument("ProjectiveIcp: " + what); };
  if (options.strides.empty()) fail("strides is empty");
  if (options.strides.size() != options.iterations.size()) {
    fail("strides has " + std::to_string(options.strides.size()) + " levels but iterations " +
         std::to_string(options.iterations.size()));
  }
  for (std::size_t k = 0; k < options.strides.size(); ++k) {
    if (options.strides[k] < 1) fail("strides[" + std::to_string(k) + "] must be >= 1");
    if (options.iterations[k] < 0) fail("iterations[" + std::to_string(k) + "] must be >= 0");
  }
  if (options.source_stride < 1) fail("source_stride must be >= 1");
  if (options.min_coarse_pairs < 0) fail("min_coarse_pairs must be >= 0 (0: off)");
  if (!(options.max_correspondence_distance_m >= 0.0)) {
    fail("max_correspondence_distance_m must be >= 0 (0: twice the kernel scale)");
  }
  if (!(options.sparse_rows_chord_offset_m >= 0.0) || !std::isfinite(options.sparse_rows_chord_offset_m))
    fail("sparse_rows_chord_offset_m must be finite and not negative (0: off)");
  if (!(options.min_normal_cosine >= -1.0 && options.min_normal_cosine <= 1.0)) {
    fail("min_normal_cosine must be within [-1, 1]");
  }
  if (!(options.area_weight_max_range_m >= 0.0) || !std::isfinite(options.area_weight_max_range_m))
    fail("area_weight_max_range_m must be finite and >= 0 (0: no area weights)");
  if (!(options.kernel.scale_m > 0.0)) fail("kernel.scale_m must be positive");
  if (!std::isfinite(options.kernel.alpha)) fail("kernel.alpha must be finite");
  if (!(options.convergence_rotation_rad >= 0.0) || !(options.convergence_translation_m >= 0.0) ||
      !(options.coarse_convergence_scale >= 1.0)) {
    fail("convergence thresholds must be >= 0 and coarse_convergence_scale >= 1");
  }
}

}  // namespace

double robustWeight(const RobustKernel& kernel, double residual_m) { return KernelWeight(kernel)(residual_m); }

ProjectiveIcp::ProjectiveIcp(RegistrationOptions options) : options_(std::move(options)) {
  validateOptions(options_);
}

void ProjectiveIcp::setTarget(const RangeImage& target) {
  if (!target.model) throw std::invalid_argument("ProjectiveIcp::setTarget: the range image has no sensor model");
  target_levels_.resize(options_.strides.size());
  for (std::size_t level = 0; level < options_.strides.size(); ++level) {
    computeVertexNormalMap(target, options_.strides[level], normalsFor(options_, *target.model), target_levels_[level]);
  }
  setTargetModel(target.model);
}

void ProjectiveIcp::setTarget(const RangeImage& target, const VertexNormalMap& full_resolution) {
  if (!target.model) throw std::invalid_argument("ProjectiveIcp::setTarget: the range image has no sensor model");
  if (full_resolution.stride != 1 || full_resolution.rows != target.rows() ||
      full_resolution.columns != target.columns() ||
      full_resolution.points.size() != std::size_t(target.rows()) * target.columns() ||
      full_resolution.normals.size() != full_resolution.points.size()) {
    throw std::invalid_argument("ProjectiveIcp::setTarget: the full-resolution map (" +
                                std::to_string(full_resolution.rows) + " x " +
                                std::to_string(full_resolution.columns) + ", stride " +
                                std::to_string(full_resolution.stride) + ") does not belong to the " +
                                std::to_string(target.rows()) + " x " + std::to_string(target.columns()) +
                                " image");
  }
  target_levels_.resize(options_.strides.size());
  for (std::size_t level = 0; level < options_.strides.size(); ++level) {
    if (options_.strides[level] == 1)
      target_levels_[level] = full_resolution;
    else
      computeVertexNormalMap(target, options_.strides[level], normalsFor(options_, *target.model), target_levels_[level]);
  }
  setTargetModel(target.model);
}

void ProjectiveIcp::setTarget(const LidarModelConstPtr& model, std::vector<VertexNormalMap>& levels) {
  if (!model) throw std::invalid_argument("ProjectiveIcp::setTarget: no sensor model");
  if (levels.size() != options_.strides.size())
    throw std::invalid_argument("ProjectiveIcp::setTarget: " + std::to_string(levels.size()) + " levels for " +
                                std::to_string(options_.strides.size()) + " strides");
  for (std::size_t level = 0; level < levels.size(); ++level) {
    const VertexNormalMap& map = levels[level];
    const int s = options_.strides[level];
    if (map.stride != s || map.rows != (model->rows() + s - 1) / s || map.columns != (model->columns() + s - 1) / s ||
        map.points.size() != std::size_t(map.rows) * map.columns || map.normals.size() != map.points.size())
      throw std::invalid_argument("ProjectiveIcp::setTarget: level " + std::to_string(level) +
                                  " does not match stride " + std::to_string(s) + " of the model");
  }
  target_levels_.swap(levels);
  setTargetModel(model);
}

void ProjectiveIcp::setTargetModel(const LidarModelConstPtr& model) {
  target_index_tables_.resize(target_levels_.size());
  for (std::size_t level = 0; level < target_levels_.size(); ++level)
    target_index_tables_[level].build(target_levels_[level], model->rows(), model->columns());
  if (model != target_model_) {
    area_weight_range_m_ = registration::areaWeightRange(options_, *model);
    pairs_without_normals_ =
        options_.pair_source_without_normals && !(normalsFor(options_, *model).max_chord_offset_m > 0.0f);
  }
  target_model_ = model;
}

RegistrationResult ProjectiveIcp::align(const RangeImage& source,
                                        const Eigen::Isometry3d& initial_target_from_source) const {
  if (!source.model) throw std::invalid_argument("ProjectiveIcp::align: the range image has no sensor model");
  computeVertexNormalMap(source, 1, normalsFor(options_, *source.model), source_map_);
  return align(source_map_, initial_target_from_source);
}

RegistrationResult ProjectiveIcp::align(const VertexNormalMap& source,
                                        const Eigen::Isometry3d& initial_target_from_source,
                                        std::size_t first_level) const {
  // An out-of-range first level still runs the finest one (a refinement).
  LevelSchedule schedule;
  schedule.first_level = std::min(first_level, options_.strides.size() - 1);
  return align(source, initial_target_from_source, schedule);
}

RegistrationResult ProjectiveIcp::align(const VertexNormalMap& source,
                                        const Eigen::Isometry3d& initial_target_from_source,
                                        const LevelSchedule& schedule) const {
  if (!target_model_) throw std::runtime_error("ProjectiveIcp::align: no target; call setTarget first");
  prepareSource(source);
  return alignSource(initial_target_from_source, schedule);
}

void ProjectiveIcp::setSource(const VertexNormalMap& source) { prepareSource(source); }

void ProjectiveIcp::prepareSource(const VertexNormalMap& source) const {
  if (source.points.size() != std::size_t(source.rows) * source.columns ||
      source.normals.size() != source.points.size() || source.stride < 1) {
    throw std::invalid_argument("ProjectiveIcp: the source map's sizes do not match its " +
                                std::to_string(source.rows) + " x " + std::to_string(source.columns) +
                                " pixels");
  }
  source_levels_.resize(options_.strides.size());
  for (std::size_t level = 0; level < options_.strides.size(); ++level) {
    // The source at the same spacing as the target level.
    const int step = std::max(1, options_.strides[level] / source.stride) * options_.source_stride;
    const int rows = (source.rows + step - 1) / step;
    const auto usable = [&](std::size_t i) {
      return (pairs_without_normals_ || std::isfinite(source.normals[i].x())) &&
             std::isfinite(source.points[i].x());
    };
    // Two parallel passes over the kept rows: how many pixels each keeps,
    // then each row's pixels copied to its offset (the same order as one
    // serial pass).
    row_offsets_.assign(std::size_t(rows) + 1, 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& block) {
      for (int r = block.begin(); r < block.end(); ++r) {
        const std::size_t first = std::size_t(r) * step * source.columns;
        std::size_t kept = 0;
        for (int column = 0; column < source.columns; column += step) kept += usable(first + column);
        row_offsets_[r + 1] = kept;
      }
    });
    for (int r = 0; r < rows; ++r) row_offsets_[r + 1] += row_offsets_[r];
    SourceLevel& kept = source_levels_[level];
    for (std::vector<float>& coordinate : kept.coordinates) coordinate.resize(row_offsets_[rows]);
    kept.columns.resize(row_offsets_[rows]);
    tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& block) {
      for (int r = block.begin(); r < block.end(); ++r) {
        const std::size_t first = std::size_t(r) * step * source.columns;
        std::size_t out = row_offsets_[r];
        for (int column = 0; column < source.columns; column += step) {
          const std::size_t i = first + column;
          if (!usable(i)) continue;
          // No normal: zero, which passes the agreement check in pairRows.
          const Eigen::Vector3f normal =
              std::isfinite(source.normals[i].x()) ? source.normals[i] : Eigen::Vector3f::Zero();
          for (int axis = 0; axis < 3; ++axis) {
            kept.coordinates[SourceLevel::kX + axis][out] = source.points[i][axis];
            kept.coordinates[SourceLevel::kNormalX + axis][out] = normal[axis];
          }
          kept.columns[out] = column * source.stride;
          ++out;
        }
      }
    });
  }
  source_full_columns_ = source.columns > 0 ? std::size_t(source.columns - 1) * source.stride + 1 : 0;
  has_source_ = true;
}

RegistrationResult ProjectiveIcp::alignSource(const Eigen::Isometry3d& initial_target_from_source,
                                              const LevelSchedule& schedule,
                                              const std::vector<ColumnMotion>& column_motion) const {
  if (!target_model_) throw std::runtime_error("ProjectiveIcp::alignSource: no target; call setTarget first");
  if (!has_source_) throw std::runtime_error("ProjectiveIcp::alignSource: no source; call setSource first");
  if (!initial_target_from_source.matrix().allFinite()) {
    throw std::invalid_argument("ProjectiveIcp: the initial pose is not finite");
  }
  if (schedule.max_iterations < 0) {
    throw std::invalid_argument("ProjectiveIcp: LevelSchedule::max_iterations must not be negative, got " +
                                std::to_string(schedule.max_iterations));
  }
  if (!column_motion.empty() && column_motion.size() < source_full_columns_) {
    throw std::invalid_argument("ProjectiveIcp::alignSource: " + std::to_string(column_motion.size()) +
                                " column motions for a source of " + std::to_string(source_full_columns_) +
                                " columns");
  }

  RegistrationResult result;
  result.target_from_source = initial_target_from_source;
  NormalEquations last;
  const std::size_t end_level = std::min(schedule.end_level, options_.strides.size());
  for (std::size_t level = schedule.first_level; level < end_level; ++level) {
    const SourceLevel& source = source_levels_[level];
    // A coarse level only has to bring the pose into the next level's basin;
    // its discrete pairs often end in a two-step cycle above the fine
    // thresholds, which would spend all of its iterations.
    const bool finest = level + 1 == options_.strides.size();
    const double looseness = finest ? 1.0 : options_.coarse_convergence_scale * options_.strides[level];
    const int iterations = schedule.max_iterations > 0 ? std::min(schedule.max_iterations, options_.iterations[level])
                                                       : options_.iterations[level];
    // Pairs further apart than the gate are not the same surface: at full
    // resolution that is correspondenceDistance(); a coarse level has to
    // capture the motion the finer ones cannot, and its pixels are s times
    // as far apart, so it accepts s times as far.
    const double gate_m = options_.correspondenceDistance() *
                          (options_.gate_grows_with_stride ? double(options_.strides[level]) : 1.0);
    const VertexNormalMap& target = target_levels_[level];
    const TargetArrays target_arrays{target.points.data()->data(), target.normals.data()->data(),
                                     target_index_tables_[level].row_start.data(),
                                     target_index_tables_[level].column.data()};
    std::array<const float*, kCoordinates> source_arrays;
    for (int k = 0; k < kCoordinates; ++k) source_arrays[k] = source.coordinates[k].data();
    const Eigen::Isometry3d level_start = result.target_from_source;
    for (int iteration = 0; iteration < iterations; ++iteration) {
      const Eigen::Matrix3f rotation = result.target_from_source.linear().cast<float>();
      const Eigen::Vector3f translation = result.target_from_source.translation().cast<float>();
      if (column_motion.empty()) {
        ColumnMotion rigid;
        rigid << rotation, translation;
        last = accumulate(source_arrays, source.columns, rigid.data(), 1, false, *target_model_, target_arrays,
                          options_, area_weight_range_m_, gate_m);
      } else {
        const std::size_t columns = column_motion.size();
        column_transforms_.resize(kTransformFloats * columns);
        for (std::size_t u = 0; u < columns; ++u) {
          ColumnMotion transform;
          transform.leftCols<3>() = rotation * column_motion[u].leftCols<3>();
          transform.col(3) = rotation * column_motion[u].col(3) + translation;
          for (int j = 0; j < kTransformFloats; ++j)
            column_transforms_[std::size_t(j) * columns + u] = transform.data()[j];
        }
        last = accumulate(source_arrays, source.columns, column_transforms_.data(), columns, true,
                          *target_model_, target_arrays, options_, area_weight_range_m_, gate_m);
      }
      ++result.iterations;
      if (!finest && last.inliers < std::size_t(options_.min_coarse_pairs)) {
        result.target_from_source = level_start;  // too few pairs to trust this level at all
        ++result.levels_passed_over;
        break;
      }
      if (last.inliers < 6) break;  // nothing to solve for; the pose stays
      const Vector6d delta = solveConstrained(last.hessian(), last.gradient);
      result.target_from_source = applyUpdate(delta, result.target_from_source);
      if (delta.head<3>().norm() < options_.convergence_rotation_rad * looseness &&
          delta.tail<3>().norm() < options_.convergence_translation_m * looseness) {
        break;
      }
    }
  }
  // Area weights scaled to a mean of 1 over the pairs: the hessian keeps
  // the scale of plain least squares (the covariance reads it).
  result.hessian = last.hessian();
  if (last.area_weights > 0.0) result.hessian *= double(last.inliers) / last.area_weights;
  result.inliers = last.inliers;
  result.condition_number = conditionNumber(result.hessian);
  result.residual_rms_m = last.inliers ? std::sqrt(last.squared_residuals / double(last.inliers)) : 0.0;
  return result;
}

}  // namespace range_image_mapping::registration
