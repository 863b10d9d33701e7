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
struct NormalEquations {
  Matrix6d hessian = Matrix6d::Zero();
  Vector6d gradient = Vector6d::Zero();
  double squared_residuals = 0.0;
  std::size_t inliers = 0;

  void add(const NormalEquations& other) {
    hessian += other.hessian;
    gradient += other.gradient;
    squared_residuals += other.squared_residuals;
    inliers += other.inliers;
  }
};

// Source points go through Pi in chunks of this size, on the stack of the
// thread that owns them.
constexpr std::size_t kProjectionChunk = 256;


// Pairs of one iteration (paper eq. 5-6) and their point-to-plane normal
// equations, in one parallel pass over the source points.
NormalEquations accumulate(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
                           const Eigen::Isometry3d& target_from_source, const LidarModel& target_model,
                           const VertexNormalMap& target, const RegistrationOptions& options) {
  const Eigen::Matrix3f rotation = target_from_source.linear().cast<float>();
  const Eigen::Vector3f translation = target_from_source.translation().cast<float>();
  const float max_distance_squared =
      float(options.max_correspondence_distance_m * options.max_correspondence_distance_m);
  const float min_cosine = float(options.min_normal_cosine);

  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, points.size(), 2048), NormalEquations{},
      [&](const tbb::blocked_range<std::size_t>& block, NormalEquations sum) {
        std::array<Eigen::Vector3f, kProjectionChunk> moved;
        std::array<ProjectedPixel, kProjectionChunk> pixels;
        std::array<uint8_t, kProjectionChunk> hits;
        for (std::size_t first = block.begin(); first < block.end(); first += kProjectionChunk) {
          const std::size_t count = std::min(kProjectionChunk, block.end() - first);
          for (std::size_t k = 0; k < count; ++k) moved[k] = rotation * points[first + k] + translation;
          target_model.projectMany(moved.data(), count, pixels.data(), hits.data());
          for (std::size_t k = 0; k < count; ++k) {
            if (!hits[k]) continue;
            const std::size_t t = levelPixelIndex(target, pixels[k]);
            const Eigen::Vector3f& target_normal = target.normals[t];
            if (!std::isfinite(target_normal.x())) continue;
            const Eigen::Vector3f& target_point = target.points[t];
            const Eigen::Vector3f difference = moved[k] - target_point;
            if (!(difference.squaredNorm() <= max_distance_squared)) continue;
            if (!((rotation * normals[first + k]).dot(target_normal) >= min_cosine)) continue;
            const double residual = target_normal.dot(difference);
            const double weight = robustWeight(options.kernel, residual);
            const Eigen::Vector3d normal = target_normal.cast<double>();
            Vector6d jacobian;
            jacobian << moved[k].cast<double>().cross(normal), normal;
            sum.hessian.selfadjointView<Eigen::Upper>().rankUpdate(jacobian, weight);
            sum.gradient += weight * residual * jacobian;
            sum.squared_residuals += residual * residual;
            ++sum.inliers;
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

double robustWeight(const RobustKernel& kernel, double residual_m) {
  const double x2 = (residual_m / kernel.scale_m) * (residual_m / kernel.scale_m);
  if (kernel.type == RobustKernel::Type::kPseudoHuber) return 1.0 / std::sqrt(1.0 + x2);
  const double alpha = kernel.alpha;
  if (alpha == 2.0) return 1.0;
  if (alpha == 0.0) return 2.0 / (x2 + 2.0);
  return std::pow(x2 / std::abs(alpha - 2.0) + 1.0, alpha / 2.0 - 1.0);
}

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

RegistrationResult ProjectiveIcp::align(const RangeImage& source,
                                        const Eigen::Isometry3d& initial_target_from_source) const {
  computeVertexNormalMap(source, 1, options_.normals, source_map_);
  return align(source_map_, initial_target_from_source);
}

RegistrationResult ProjectiveIcp::align(const VertexNormalMap& source,
                                        const Eigen::Isometry3d& initial_target_from_source,
                                        std::size_t first_level) const {
  if (!target_model_) throw std::runtime_error("ProjectiveIcp::align: no target; call setTarget first");
  if (!initial_target_from_source.matrix().allFinite()) {
    throw std::invalid_argument("ProjectiveIcp::align: the initial pose is not finite");
  }
  if (source.points.size() != std::size_t(source.rows) * source.columns ||
      source.normals.size() != source.points.size() || source.stride < 1) {
    throw std::invalid_argument("ProjectiveIcp::align: the source map's sizes do not match its " +
                                std::to_string(source.rows) + " x " + std::to_string(source.columns) +
                                " pixels");
  }

  RegistrationResult result;
  result.target_from_source = initial_target_from_source;
  NormalEquations last;
  for (std::size_t level = std::min(first_level, options_.strides.size() - 1); level < options_.strides.size();
       ++level) {
    // The source at the same spacing as the target level.
    const int step = std::max(1, options_.strides[level] / source.stride) * options_.source_stride;
    source_points_.clear();
    source_normals_.clear();
    for (int row = 0; row < source.rows; row += step) {
      for (int column = 0; column < source.columns; column += step) {
        const std::size_t i = std::size_t(row) * source.columns + column;
        if (!std::isfinite(source.normals[i].x()) || !std::isfinite(source.points[i].x())) continue;
        source_points_.push_back(source.points[i]);
        source_normals_.push_back(source.normals[i]);
      }
    }
    // A coarse level only has to bring the pose into the next level's basin;
    // its discrete pairs often end in a two-step cycle above the fine
    // thresholds, which would spend all of its iterations.
    const bool finest = level + 1 == options_.strides.size();
    const double looseness = finest ? 1.0 : options_.coarse_convergence_scale * options_.strides[level];
    for (int iteration = 0; iteration < options_.iterations[level]; ++iteration) {
      last = accumulate(source_points_, source_normals_, result.target_from_source, *target_model_,
                        target_levels_[level], options_);
      ++result.iterations;
      if (last.inliers < 6) break;  // nothing to solve for; the pose stays
      const Matrix6d hessian = last.hessian.selfadjointView<Eigen::Upper>();
      const Vector6d delta = solveConstrained(hessian, last.gradient);
      result.target_from_source = applyUpdate(delta, result.target_from_source);
      if (delta.head<3>().norm() < options_.convergence_rotation_rad * looseness &&
          delta.tail<3>().norm() < options_.convergence_translation_m * looseness) {
        break;
      }
    }
  }
  result.hessian = last.hessian.selfadjointView<Eigen::Upper>();
  result.inliers = last.inliers;
  result.condition_number = conditionNumber(result.hessian);
  result.residual_rms_m = last.inliers ? std::sqrt(last.squared_residuals / double(last.inliers)) : 0.0;
  return result;
}

}  // namespace range_image_mapping::registration
