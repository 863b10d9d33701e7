#include "range_image_mapping/registration/local_model.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::registration {
namespace {

constexpr uint32_t kNoRange = std::numeric_limits<uint32_t>::max();
constexpr uint32_t kNoPoint = std::numeric_limits<uint32_t>::max();
// Returns of one surface lie within this of its nearest one (noise, the
// spread of a pixel's footprint on slanted surfaces).
constexpr float kSurfaceThickness_m = 0.1f;
constexpr float kSurfaceThicknessShare = 0.01f;

// Positive floats order as their bit patterns.
uint32_t rangeBits(float range) {
  uint32_t bits;
  std::memcpy(&bits, &range, sizeof bits);
  return bits;
}

void keepSmallest(uint32_t& slot, uint32_t value) {
  uint32_t current = __atomic_load_n(&slot, __ATOMIC_RELAXED);
  while (value < current &&
         !__atomic_compare_exchange_n(&slot, &current, value, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
}

}  // namespace

LocalModel::LocalModel(LocalModelOptions options) : options_(options) {
  if (options_.keyframes < 1) throw std::invalid_argument("local model: keyframes must be at least 1");
  if (!(options_.keyframe_distance_m >= 0.0) || !(options_.keyframe_angle_rad >= 0.0) ||
      !std::isfinite(options_.keyframe_distance_m) || !std::isfinite(options_.keyframe_angle_rad))
    throw std::invalid_argument("local model: keyframe distance and angle must be finite and not negative");
  if (!(options_.normal_radius_m >= 0.0) || !std::isfinite(options_.normal_radius_m))
    throw std::invalid_argument("local model: normal_radius_m must be finite and not negative (0: off)");
}

void LocalModel::clear() { keyframes_.clear(); }

Eigen::Isometry3d LocalModel::newestPose() const {
  return keyframes_.empty() ? Eigen::Isometry3d::Identity() : keyframes_.back().odom_from_lidar;
}

bool LocalModel::wantsKeyframe(const Eigen::Isometry3d& odom_from_lidar) const {
  if (keyframes_.empty() || keyframes_.back().provisional) return true;
  const Eigen::Isometry3d from_newest = keyframes_.back().odom_from_lidar.inverse() * odom_from_lidar;
  const bool distance = options_.keyframe_distance_m > 0.0, angle = options_.keyframe_angle_rad > 0.0;
  if (!distance && !angle) return true;
  return (distance && from_newest.translation().norm() >= options_.keyframe_distance_m) ||
         (angle && Eigen::AngleAxisd(from_newest.linear()).angle() >= options_.keyframe_angle_rad);
}

void LocalModel::add(const std::vector<VertexNormalMap>& levels, const Eigen::Isometry3d& odom_from_lidar,
                     bool provisional) {
  if (!keyframes_.empty() && keyframes_.back().provisional) keyframes_.pop_back();
  if (!keyframes_.empty() && keyframes_.back().levels.size() != levels.size())
    throw std::invalid_argument("local model: a keyframe with " + std::to_string(levels.size()) +
                                " levels after ones with " + std::to_string(keyframes_.back().levels.size()));
  Keyframe keyframe;
  if (keyframes_.size() >= options_.keyframes) {  // reuse the oldest one's buffers
    keyframe = std::move(keyframes_.front());
    keyframes_.pop_front();
  }
  keyframe.odom_from_lidar = odom_from_lidar;
  keyframe.provisional = provisional;
  keyframe.levels.resize(levels.size());
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const VertexNormalMap& map = levels[l];
    Level& level = keyframe.levels[l];
    level.stride = map.stride;
    level.points.clear();
    level.normals.clear();
    const bool model_normals = options_.normal_radius_m > 0.0;
    for (std::size_t i = 0; i < map.points.size(); ++i) {
      if (!map.points[i].allFinite() || (!model_normals && !map.normals[i].allFinite())) continue;
      level.points.push_back(map.points[i]);
      level.normals.push_back(map.normals[i]);
    }
  }
  keyframes_.push_back(std::move(keyframe));
  if (options_.normal_radius_m > 0.0) computeModelNormals();
}

namespace {

// Voxel coordinates packed into one key, z in the low bits (so a column of
// voxels is a run of keys).
constexpr int kVoxelBits = 21;
constexpr int64_t kVoxelOffset = int64_t(1) << (kVoxelBits - 1);
uint64_t voxelKey(int64_t x, int64_t y, int64_t z) {
  const auto part = [](int64_t v) { return uint64_t(std::clamp<int64_t>(v + kVoxelOffset, 0, (int64_t(1) << kVoxelBits) - 1)); };
  return (part(x) << (2 * kVoxelBits)) | (part(y) << kVoxelBits) | part(z);
}

// A neighbourhood is a plane when its second axis spans at least kMinSpan
// of the radius (more than one ring's line) and its thickness is at most
// kMaxThickness of that span (not a crease, a kerb, a corner).
constexpr double kMinSpan = 0.15, kMaxThickness = 0.3;

}  // namespace

// The neighbourhood of a point is the block of 3 x 3 x 3 voxels around its
// voxel, 2 normal_radius_m wide: every point of a voxel shares it, so the
// plane is fitted once per voxel, from the voxels' moments (count, mean,
// scatter about the mean) joined by the parallel-axis theorem, instead of
// once per point over its neighbours.
void LocalModel::computeModelNormals() {
  const double voxel_size = 2.0 * options_.normal_radius_m / 3.0;
  Keyframe& newest = keyframes_.back();
  const Eigen::Isometry3d newest_from_odom = newest.odom_from_lidar.inverse();
  // The finest level's points of every keyframe, in the newest one's frame.
  grid_points_.clear();
  for (const Keyframe& keyframe : keyframes_) {
    const Eigen::Isometry3f newest_from_keyframe = (newest_from_odom * keyframe.odom_from_lidar).cast<float>();
    for (const Eigen::Vector3f& point : keyframe.levels.back().points)
      grid_points_.push_back(newest_from_keyframe * point);
  }
  const float inverse_size = float(1.0 / voxel_size);
  const auto keyOf = [&](const Eigen::Vector3f& point) {
    return voxelKey(int64_t(std::floor(point.x() * inverse_size)), int64_t(std::floor(point.y() * inverse_size)),
                    int64_t(std::floor(point.z() * inverse_size)));
  };
  grid_order_.resize(grid_points_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, grid_points_.size(), 8192),
                    [&](const tbb::blocked_range<std::size_t>& block) {
                      for (std::size_t i = block.begin(); i < block.end(); ++i)
                        grid_order_[i] = {keyOf(grid_points_[i]), uint32_t(i)};
                    });
  tbb::parallel_sort(grid_order_.begin(), grid_order_.end());
  voxel_keys_.clear();
  voxel_runs_.clear();
  for (std::size_t i = 0; i < grid_order_.size(); ++i) {
    if (i == 0 || grid_order_[i].first != grid_order_[i - 1].first) {
      voxel_keys_.push_back(grid_order_[i].first);
      voxel_runs_.push_back({uint32_t(i), uint32_t(i)});
    }
    voxel_runs_.back().second = uint32_t(i + 1);
  }
  // Each voxel's moments, about its first point (float sums stay exact).
  voxel_moments_.resize(voxel_keys_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, voxel_keys_.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& block) {
                      for (std::size_t v = block.begin(); v < block.end(); ++v) {
                        const auto [begin, end] = voxel_runs_[v];
                        const Eigen::Vector3d origin = grid_points_[grid_order_[begin].second].cast<double>();
                        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
                        Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
                        for (uint32_t k = begin; k < end; ++k) {
                          const Eigen::Vector3d d = grid_points_[grid_order_[k].second].cast<double>() - origin;
                          sum += d;
                          outer.noalias() += d * d.transpose();
                        }
                        VoxelMoments& moments = voxel_moments_[v];
                        moments.count = double(end - begin);
                        moments.mean = origin + sum / moments.count;
                        moments.scatter = outer - sum * sum.transpose() / moments.count;
                      }
                    });
  // Each voxel's plane over its block.
  const double min_span_squared = (kMinSpan * options_.normal_radius_m) * (kMinSpan * options_.normal_radius_m);
  const double max_thickness_squared = kMaxThickness * kMaxThickness;
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  voxel_normals_.resize(voxel_keys_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, voxel_keys_.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& block) {
                      for (std::size_t v = block.begin(); v < block.end(); ++v) {
                        const uint64_t key = voxel_keys_[v];
                        const VoxelMoments& centre = voxel_moments_[v];
                        // The block's moments about the centre voxel's mean.
                        double count = 0.0;
                        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
                        Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
                        for (int dx = -1; dx <= 1; ++dx)
                          for (int dy = -1; dy <= 1; ++dy) {
                            // z in the low bits: a column of three voxels is a run of keys.
                            const uint64_t first = key + (uint64_t(int64_t(dx)) << (2 * kVoxelBits)) +
                                                   (uint64_t(int64_t(dy)) << kVoxelBits) - 1;
                            for (auto it = std::lower_bound(voxel_keys_.begin(), voxel_keys_.end(), first);
                                 it != voxel_keys_.end() && *it <= first + 2; ++it) {
                              const VoxelMoments& other = voxel_moments_[std::size_t(it - voxel_keys_.begin())];
                              const Eigen::Vector3d offset = other.mean - centre.mean;
                              count += other.count;
                              sum += other.count * offset;
                              scatter += other.scatter + other.count * offset * offset.transpose();
                            }
                          }
                        voxel_normals_[v] = Eigen::Vector3f::Constant(kNaN);
                        if (count < 6.0) continue;
                        const Eigen::Vector3d mean = sum / count;
                        const Eigen::Matrix3d covariance = scatter / count - mean * mean.transpose();
                        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
                        solver.computeDirect(covariance);
                        const Eigen::Vector3d eigenvalues = solver.eigenvalues();  // ascending
                        // A plane: spread in two directions (not one ring's line) and thin.
                        if (!(eigenvalues(1) >= min_span_squared) ||
                            !(eigenvalues(0) <= max_thickness_squared * eigenvalues(1)))
                          continue;
                        const Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
                        if (normal.allFinite()) voxel_normals_[v] = normal;
                      }
                    });
  // Where the model has no plane (a far wall's rings a metre apart), the
  // keyframe's own normal, if any, stays.
  for (Level& level : newest.levels)
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, level.points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        for (std::size_t i = block.begin(); i < block.end(); ++i) {
                          const Eigen::Vector3f& point = level.points[i];
                          const auto it = std::lower_bound(voxel_keys_.begin(), voxel_keys_.end(), keyOf(point));
                          if (it == voxel_keys_.end() || *it != keyOf(point)) continue;
                          const Eigen::Vector3f& normal = voxel_normals_[std::size_t(it - voxel_keys_.begin())];
                          if (normal.allFinite())
                            level.normals[i] = normal.dot(point) > 0.0f ? Eigen::Vector3f(-normal) : normal;
                        }
                      });
}

void LocalModel::render(const LidarModel& model, const Eigen::Isometry3d& odom_from_view,
                        std::vector<VertexNormalMap>& levels) const {
  const std::size_t level_count = keyframes_.empty() ? 0 : keyframes_.back().levels.size();
  levels.resize(level_count);
  nearest_.resize(level_count);
  winner_.resize(level_count);
  const Eigen::Isometry3d view_from_odom = odom_from_view.inverse();
  view_from_keyframe_.resize(keyframes_.size());
  // Keyframes newest first, so that ties go to the newer one.
  for (std::size_t k = 0; k < keyframes_.size(); ++k)
    view_from_keyframe_[k] = (view_from_odom * keyframes_[keyframes_.size() - 1 - k].odom_from_lidar).cast<float>();
  const auto keyframe = [&](std::size_t k) -> const Keyframe& { return keyframes_[keyframes_.size() - 1 - k]; };
  constexpr std::size_t kChunk = 2048;
  for (std::size_t l = 0; l < level_count; ++l) {
    const int s = keyframes_.back().levels[l].stride;
    VertexNormalMap& level = levels[l];
    level.stride = s;
    level.rows = (model.rows() + s - 1) / s;
    level.columns = (model.columns() + s - 1) / s;
    const std::size_t size = std::size_t(level.rows) * level.columns;
    std::vector<uint32_t>& nearest = nearest_[l];
    std::vector<uint32_t>& winner = winner_[l];
    nearest.assign(size, kNoRange);
    winner.assign(size, kNoPoint);
    first_point_.assign(keyframes_.size() + 1, 0);
    for (std::size_t k = 0; k < keyframes_.size(); ++k)
      first_point_[k + 1] = first_point_[k] + keyframe(k).levels[l].points.size();
    if (first_point_.back() >= kNoPoint) throw std::length_error("local model: too many points to render");
    pixel_of_point_.resize(first_point_.back());
    range_of_point_.resize(first_point_.back());
    pixel_tables_.build(level, model.rows(), model.columns());
    // The keyframes' points of this level in the same order (a deque's
    // indexing costs more than the transform in the per-pixel loop below).
    level_points_.resize(keyframes_.size());
    for (std::size_t k = 0; k < keyframes_.size(); ++k) level_points_[k] = &keyframe(k).levels[l];

    // Pass 1: every point's pixel and range, and each pixel's nearest range.
    for (std::size_t k = 0; k < keyframes_.size(); ++k) {
      const Level& points = keyframe(k).levels[l];
      const Eigen::Isometry3f& view_from_keyframe = view_from_keyframe_[k];
      const std::size_t first = first_point_[k];
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.points.size(), kChunk),
                        [&](const tbb::blocked_range<std::size_t>& block) {
                          Eigen::Vector3f moved[kChunk];
                          ProjectedPixel pixels[kChunk];
                          uint8_t hits[kChunk];
                          const std::size_t n = block.size();
                          for (std::size_t i = 0; i < n; ++i) moved[i] = view_from_keyframe * points.points[block.begin() + i];
                          model.projectMany(moved, n, pixels, hits);
                          for (std::size_t i = 0; i < n; ++i) {
                            const std::size_t number = first + block.begin() + i;
                            if (!hits[i]) {
                              pixel_of_point_[number] = kNoPoint;
                              continue;
                            }
                            const uint32_t pixel = uint32_t(pixel_tables_.index(pixels[i]));
                            pixel_of_point_[number] = pixel;
                            range_of_point_[number] = pixels[i].range;
                            keepSmallest(nearest[pixel], rangeBits(pixels[i].range));
                          }
                        });
    }
    // Points without a normal take part in the z-buffer (they occlude) but
    // cannot win a pixel.
    const auto has_normal = [&](std::size_t number) {
      std::size_t k = 0;
      while (number >= first_point_[k + 1]) ++k;
      return std::isfinite(level_points_[k]->normals[number - first_point_[k]].x());
    };
    // Pass 2: of the points on the nearest surface, the newest keyframe's.
    // The nearest point itself would be biased towards the sensor by the
    // noise: the least of several noisy ranges of one surface.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, first_point_.back(), 8192),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        for (std::size_t number = block.begin(); number < block.end(); ++number) {
                          const uint32_t pixel = pixel_of_point_[number];
                          if (pixel == kNoPoint || !has_normal(number)) continue;
                          const float range = range_of_point_[number];
                          float front;
                          const uint32_t bits = __atomic_load_n(&nearest[pixel], __ATOMIC_RELAXED);
                          std::memcpy(&front, &bits, sizeof front);
                          if (range <= front + std::max(kSurfaceThickness_m, kSurfaceThicknessShare * front))
                            keepSmallest(winner[pixel], uint32_t(number));
                        }
                      });

    // Each pixel's winner, moved into the view.
    level.points.resize(size);
    level.normals.resize(size);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, size, 4096), [&](const tbb::blocked_range<std::size_t>& block) {
      constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
      for (std::size_t p = block.begin(); p < block.end(); ++p) {
        const uint32_t number = winner[p];
        if (number == kNoPoint) {
          level.points[p] = level.normals[p] = Eigen::Vector3f::Constant(kNaN);
          continue;
        }
        std::size_t k = 0;
        while (number >= first_point_[k + 1]) ++k;
        const Level& points = *level_points_[k];
        const std::size_t i = number - first_point_[k];
        level.points[p] = view_from_keyframe_[k] * points.points[i];
        level.normals[p] = view_from_keyframe_[k].linear() * points.normals[i];
      }
    });
  }
}

}  // namespace range_image_mapping::registration
