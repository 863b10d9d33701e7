#include "range_image_mapping/registration/projective_icp.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Eigenvalues>

#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::registration {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// Normal equations of one Gauss-Newton step, summed per thread and joined.
// The hessian is kept as its 21 upper-triangle entries (row by row): a
// rank-one update of those is plain arithmetic the compiler unrolls, where a
// generic symmetric product is a call per pair.
struct NormalEquations {
  std::array<double, 21> hessian_upper{};
  Vector6d gradient = Vector6d::Zero();
  double squared_residuals = 0.0;
  std::size_t inliers = 0;

  void add(const NormalEquations& other) {
    for (std::size_t k = 0; k < hessian_upper.size(); ++k) hessian_upper[k] += other.hessian_upper[k];
    gradient += other.gradient;
    squared_residuals += other.squared_residuals;
    inliers += other.inliers;
  }
  // J^T W J += weight J J^T; J^T W r += weight residual J.
  void addPair(const double (&jacobian)[6], double weight, double residual) {
    std::size_t k = 0;
    for (int i = 0; i < 6; ++i) {
      const double weighted = weight * jacobian[i];
      for (int j = i; j < 6; ++j) hessian_upper[k++] += weighted * jacobian[j];
      gradient(i) += weighted * residual;
    }
    squared_residuals += residual * residual;
    ++inliers;
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

// Source points go through Pi in chunks of this size, on the stack of the
// thread that owns them.
constexpr std::size_t kProjectionChunk = 256;

// Where each source point goes in the target frame: one rigid transform,
// or one per full-resolution column (the target_from_source transform
// composed with the column's deskew motion).
struct RigidMotion {
  Eigen::Matrix3f rotation;
  Eigen::Vector3f translation;
  const Eigen::Matrix3f& rotationOf(int /*column*/) const { return rotation; }
  Eigen::Vector3f move(const Eigen::Vector3f& point, int /*column*/) const { return rotation * point + translation; }
};
struct PerColumnMotion {
  const ColumnMotion* transforms;
  Eigen::Matrix3f rotationOf(int column) const { return transforms[column].leftCols<3>(); }
  Eigen::Vector3f move(const Eigen::Vector3f& point, int column) const {
    return transforms[column].leftCols<3>() * point + transforms[column].col(3);
  }
};

// Pairs of one iteration (paper eq. 5-6) and their point-to-plane normal
// equations, in one parallel pass over the source points.
template <typename Motion>
NormalEquations accumulate(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
                           const std::vector<int>& columns, const Motion& motion, const LidarModel& target_model,
                           const VertexNormalMap& target, const RegistrationOptions& options, double gate_m) {
  const float max_distance_squared = float(gate_m * gate_m);
  const float min_cosine = float(options.min_normal_cosine);
  const KernelWeight weight_of(options.kernel);

  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, points.size(), 2048), NormalEquations{},
      [&](const tbb::blocked_range<std::size_t>& block, NormalEquations sum) {
        std::array<Eigen::Vector3f, kProjectionChunk> moved, pair_points, pair_normals;
        std::array<ProjectedPixel, kProjectionChunk> pixels;
        std::array<uint8_t, kProjectionChunk> hits;
        alignas(16) std::array<float, kProjectionChunk> residuals, weights;
        for (std::size_t first = block.begin(); first < block.end(); first += kProjectionChunk) {
          const std::size_t count = std::min(kProjectionChunk, block.end() - first);
          for (std::size_t k = 0; k < count; ++k) moved[k] = motion.move(points[first + k], columns[first + k]);
          target_model.projectMany(moved.data(), count, pixels.data(), hits.data());
          // Association first, then the arithmetic on the pairs found: the
          // weights' square roots and divisions vectorise.
          std::size_t pairs = 0;
          for (std::size_t k = 0; k < count; ++k) {
            if (!hits[k]) continue;
            const std::size_t t = levelPixelIndex(target, pixels[k]);
            const Eigen::Vector3f& target_normal = target.normals[t];
            if (!std::isfinite(target_normal.x())) continue;
            const Eigen::Vector3f difference = moved[k] - target.points[t];
            if (!(difference.squaredNorm() <= max_distance_squared)) continue;
            const Eigen::Vector3f source_normal = motion.rotationOf(columns[first + k]) * normals[first + k];
            if (!(source_normal.dot(target_normal) >= min_cosine)) continue;
            pair_points[pairs] = moved[k];
            pair_normals[pairs] = target_normal;
            residuals[pairs] = target_normal.dot(difference);
            ++pairs;
          }
          weight_of.weights(residuals.data(), pairs, weights.data());
          for (std::size_t k = 0; k < pairs; ++k) {
            const Eigen::Vector3f moment = pair_points[k].cross(pair_normals[k]);
            const double jacobian[6] = {moment.x(),          moment.y(),          moment.z(),
                                        pair_normals[k].x(), pair_normals[k].y(), pair_normals[k].z()};
            sum.addPair(jacobian, weights[k], residuals[k]);
          }
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
  if (!(options.max_correspondence_distance_m > 0.0)) fail("max_correspondence_distance_m must be positive");
  if (!(options.min_normal_cosine >= -1.0 && options.min_normal_cosine <= 1.0)) {
    fail("min_normal_cosine must be within [-1, 1]");
  }
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
  target_levels_.resize(options_.strides.size());
  for (std::size_t level = 0; level < options_.strides.size(); ++level) {
    computeVertexNormalMap(target, options_.strides[level], options_.normals, target_levels_[level]);
  }
  target_model_ = target.model;
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
      computeVertexNormalMap(target, options_.strides[level], options_.normals, target_levels_[level]);
  }
  target_model_ = target.model;
}

RegistrationResult ProjectiveIcp::align(const RangeImage& source,
                                        const Eigen::Isometry3d& initial_target_from_source) const {
  computeVertexNormalMap(source, 1, options_.normals, source_map_);
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
    SourceLevel& kept = source_levels_[level];
    kept.points.clear();
    kept.normals.clear();
    kept.columns.clear();
    for (int row = 0; row < source.rows; row += step) {
      for (int column = 0; column < source.columns; column += step) {
        const std::size_t i = std::size_t(row) * source.columns + column;
        if (!std::isfinite(source.normals[i].x()) || !std::isfinite(source.points[i].x())) continue;
        kept.points.push_back(source.points[i]);
        kept.normals.push_back(source.normals[i]);
        kept.columns.push_back(column * source.stride);
      }
    }
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
    // resolution that is max_correspondence_distance_m; a coarse level has
    // to capture the motion the finer ones cannot, and its pixels are s
    // times as far apart, so it accepts s times as far.
    const double gate_m = options_.max_correspondence_distance_m *
                          (options_.gate_grows_with_stride ? double(options_.strides[level]) : 1.0);
    for (int iteration = 0; iteration < iterations; ++iteration) {
      const Eigen::Matrix3f rotation = result.target_from_source.linear().cast<float>();
      const Eigen::Vector3f translation = result.target_from_source.translation().cast<float>();
      if (column_motion.empty()) {
        last = accumulate(source.points, source.normals, source.columns, RigidMotion{rotation, translation},
                          *target_model_, target_levels_[level], options_, gate_m);
      } else {
        column_transforms_.resize(column_motion.size());
        for (std::size_t u = 0; u < column_motion.size(); ++u) {
          column_transforms_[u].leftCols<3>() = rotation * column_motion[u].leftCols<3>();
          column_transforms_[u].col(3) = rotation * column_motion[u].col(3) + translation;
        }
        last = accumulate(source.points, source.normals, source.columns, PerColumnMotion{column_transforms_.data()},
                          *target_model_, target_levels_[level], options_, gate_m);
      }
      ++result.iterations;
      if (last.inliers < 6) break;  // nothing to solve for; the pose stays
      const Vector6d delta = solveConstrained(last.hessian(), last.gradient);
      result.target_from_source = applyUpdate(delta, result.target_from_source);
      if (delta.head<3>().norm() < options_.convergence_rotation_rad * looseness &&
          delta.tail<3>().norm() < options_.convergence_translation_m * looseness) {
        break;
      }
    }
  }
  result.hessian = last.hessian();
  result.inliers = last.inliers;
  result.condition_number = conditionNumber(result.hessian);
  result.residual_rms_m = last.inliers ? std::sqrt(last.squared_residuals / double(last.inliers)) : 0.0;
  return result;
}

}  // namespace range_image_mapping::registration
