#include "range_image_mapping/registration/local_model.h"

#include "range_image_mapping/point_arrays.h"

#include "range_image_mapping/registration/projective_icp.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

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

// The model fills between a sparse sensor's rings with the rings of
// keyframes taken elsewhere. Keyframes 0.5 m apart lay their rings on the
// far ground almost onto one another (a ring's spacing there grows as
// range^2 d / height), so the planes fitted across them tilt with the
// keyframes' attitude errors, and the odometry chains one error per
// keyframe. Measured (issue 14): a VLP-16 (2 deg) drifts least with
// keyframes about 2 m apart, the HDL-32E (1.33 deg) at 1.33 m (at 0.89 m its
// RPE got worse); the OS-0-128 (0.7 deg) lost 0.3 mm ATE indoors at 0.72 m,
// so sensors with rows under a degree apart (not sparseRows) keep the
// option's distance.
constexpr double kKeyframeDistancePerSpacing_m_rad = 180.0 / M_PI;  // a metre per degree

// Positive floats order as their bit patterns.
uint32_t rangeBits(float range) {
  uint32_t bits;
  std::memcpy(&bits, &range, sizeof bits);
  return bits;
}

// Render lanes: consecutive runs of the points, each with z-buffers of its
// own (plain minimums; shared buffers needed atomic compare-and-swap, whose
// cache lines the two cores took from each other), merged per pixel after.
// A few lanes per thread balance the load.
constexpr std::size_t kLanesPerThread = 2;

// render's pass 1 per chunk of points: the moved points as x, y, z arrays
// and their pixels, left uninitialised (a ProjectedPixel array would be
// zeroed first; projectMany writes every entry that is read).
constexpr std::size_t kRenderChunk = 2048;
struct ChunkBuffers {
  alignas(32) float x[kRenderChunk], y[kRenderChunk], z[kRenderChunk];
  union {
    ProjectedPixel pixels[kRenderChunk];
  };
  uint8_t hits[kRenderChunk];
  ChunkBuffers() {}
};

}  // namespace

LocalModel::LocalModel(LocalModelOptions options) : options_(options) {
  if (options_.keyframes < 1) throw std::invalid_argument("local model: keyframes must be at least 1");
  if (!(options_.keyframe_distance_m >= 0.0) || !(options_.keyframe_angle_rad >= 0.0) ||
      !std::isfinite(options_.keyframe_distance_m) || !std::isfinite(options_.keyframe_angle_rad))
    throw std::invalid_argument("local model: keyframe distance and angle must be finite and not negative");
  if (!(options_.normal_radius_m >= 0.0) || !std::isfinite(options_.normal_radius_m))
    throw std::invalid_argument("local model: normal_radius_m must be finite and not negative (0: off)");
  if (!(options_.keyframe_range_share >= 0.0) || !std::isfinite(options_.keyframe_range_share) ||
      !(options_.max_keyframe_distance_m >= 0.0) || !std::isfinite(options_.max_keyframe_distance_m))
    throw std::invalid_argument("local model: keyframe_range_share and max_keyframe_distance_m must be finite and "
                                "not negative (0: off)");
}

void LocalModel::clear() { keyframes_.clear(); }

Eigen::Isometry3d LocalModel::newestPose() const {
  return keyframes_.empty() ? Eigen::Isometry3d::Identity() : keyframes_.back().odom_from_lidar;
}

double keyframeDistance(const LocalModelOptions& options, const LidarModel& model) {
  if (!(options.keyframe_distance_m > 0.0)) return 0.0;
  if (!sparseRows(model)) return options.keyframe_distance_m;
  return std::max(options.keyframe_distance_m,
                  kKeyframeDistancePerSpacing_m_rad * model.intrinsics().medianRowSpacingRad());
}

double LocalModel::keyframeDistance(const LidarModel& model) const {
  const double least_m = registration::keyframeDistance(options_, model);
  if (!(least_m > 0.0)) return 0.0;
  return std::max(least_m, std::min(options_.max_keyframe_distance_m,
                                    options_.keyframe_range_share * newestMedianRange()));
}

bool LocalModel::wantsKeyframe(const Eigen::Isometry3d& odom_from_lidar, const LidarModel& model) const {
  if (keyframes_.empty() || keyframes_.back().provisional) return true;
  const Eigen::Isometry3d from_newest = keyframes_.back().odom_from_lidar.inverse() * odom_from_lidar;
  const double distance_m = keyframeDistance(model);
  const bool distance = distance_m > 0.0, angle = options_.keyframe_angle_rad > 0.0;
  if (!distance && !angle) return true;
  return (distance && from_newest.translation().norm() >= distance_m) ||
         (angle && Eigen::AngleAxisd(from_newest.linear()).angle() >= options_.keyframe_angle_rad);
}

void LocalModel::add(const std::vector<VertexNormalMap>& levels, const Eigen::Isometry3d& odom_from_lidar,
                     bool provisional, bool model_normals) {
  model_normals = model_normals && options_.normal_radius_m > 0.0;
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
  // Each level's pixels kept, in pixel order: counted per fixed chunk, then
  // copied chunk by chunk in parallel.
  constexpr std::size_t kCopyChunk = 4096;
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const VertexNormalMap& map = levels[l];
    Level& level = keyframe.levels[l];
    level.stride = map.stride;
    const auto kept = [&](std::size_t i) {
      return map.points[i].allFinite() && (model_normals || map.normals[i].allFinite());
    };
    const std::size_t chunks = (map.points.size() + kCopyChunk - 1) / kCopyChunk;
    kept_before_chunk_.assign(chunks + 1, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks), [&](const tbb::blocked_range<std::size_t>& block) {
      for (std::size_t chunk = block.begin(); chunk < block.end(); ++chunk) {
        const std::size_t end = std::min(map.points.size(), (chunk + 1) * kCopyChunk);
        std::size_t count = 0;
        for (std::size_t i = chunk * kCopyChunk; i < end; ++i) count += kept(i);
        kept_before_chunk_[chunk + 1] = count;
      }
    });
    for (std::size_t chunk = 0; chunk < chunks; ++chunk) kept_before_chunk_[chunk + 1] += kept_before_chunk_[chunk];
    level.points.resize(kept_before_chunk_.back());
    level.normals.resize(kept_before_chunk_.back());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks), [&](const tbb::blocked_range<std::size_t>& block) {
      for (std::size_t chunk = block.begin(); chunk < block.end(); ++chunk) {
        const std::size_t end = std::min(map.points.size(), (chunk + 1) * kCopyChunk);
        std::size_t next = kept_before_chunk_[chunk];
        for (std::size_t i = chunk * kCopyChunk; i < end; ++i) {
          if (!kept(i)) continue;
          level.points[next] = map.points[i];
          level.normals[next] = map.normals[i];
          ++next;
        }
      }
    });
  }
  // The scene's scale: the median of every kRangeSampleStep-th point's range.
  constexpr std::size_t kRangeSampleStep = 16;
  ranges_.clear();
  if (!keyframe.levels.empty())
    for (std::size_t i = 0; i < keyframe.levels.back().points.size(); i += kRangeSampleStep)
      ranges_.push_back(keyframe.levels.back().points[i].norm());
  keyframe.median_range_m = 0.0;
  if (!ranges_.empty()) {
    std::nth_element(ranges_.begin(), ranges_.begin() + ranges_.size() / 2, ranges_.end());
    keyframe.median_range_m = ranges_[ranges_.size() / 2];
  }
  keyframes_.push_back(std::move(keyframe));
  if (model_normals) computeModelNormals();
}

namespace {

// A neighbourhood is a plane when its second axis spans at least kMinSpan
// of the radius (more than one ring's line) and its thickness is at most
// kMaxThickness of that span (not a crease, a kerb, a corner).
constexpr double kMinSpan = 0.15, kMaxThickness = 0.3;
constexpr uint32_t kNoVoxel = std::numeric_limits<uint32_t>::max();

// floor(value) for finite values within int's range, without a call to floorf.
int floorToInt(float value) {
  const int truncated = int(value);
  return truncated - (value < float(truncated));
}

// A voxel's map: high bits of its hash mixed again (the maps index their
// buckets by the low bits, which must stay spread within each map).
uint8_t partitionOfHash(std::size_t hash) {
  static_assert(LocalModel::kVoxelPartitions == 8, "three bits");
  return uint8_t((uint64_t(hash) * 0x9E3779B97F4A7C15ull) >> 61);
}

static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float) && sizeof(LatticeKey) == 3 * sizeof(int), "xyz triples");

// Points (xyz triples) moved by [R | t] (a 4 x 4 matrix's first 12 floats,
// column-major), each one's voxel (xyz triples) of the grid 1 / inverse_size
// wide and its map: as keyOf and partitionOfHash, over plain arrays so that it
// vectorises. Cloned for AVX2 and AVX-512 (no fused multiply-adds: the same
// sums in the same order as Eigen's product, so the same floats).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void moveAndBin(const float* points, std::size_t count, const float* transform, float inverse_size,
                float* __restrict moved, int* __restrict keys, uint8_t* __restrict partitions) {
  for (std::size_t k = 0; k < count; ++k) {
    const float* point = points + 3 * k;
    int key[3];
    for (int axis = 0; axis < 3; ++axis) {
      const float value = ((transform[axis] * point[0] + transform[4 + axis] * point[1]) + transform[8 + axis] * point[2]) +
                          transform[12 + axis];
      moved[3 * k + axis] = value;
      key[axis] = floorToInt(value * inverse_size);
      keys[3 * k + axis] = key[axis];
    }
    partitions[k] = partitionOfHash(LatticeKeyHash()(LatticeKey(key[0], key[1], key[2])));
  }
}


}  // namespace

void LocalModel::PartitionOrder::sort(const std::vector<uint8_t>& partitions) {
  // Each chunk's count per map, then each map's numbers chunk by chunk: the
  // same order as one pass over them would give.
  constexpr std::size_t kChunk = 8192;
  const std::size_t chunks = (partitions.size() + kChunk - 1) / kChunk;
  chunk_counts.assign(chunks * kVoxelPartitions, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks), [&](const tbb::blocked_range<std::size_t>& block) {
    for (std::size_t chunk = block.begin(); chunk < block.end(); ++chunk) {
      uint32_t* counts = &chunk_counts[chunk * kVoxelPartitions];
      const std::size_t end = std::min(partitions.size(), (chunk + 1) * kChunk);
      for (std::size_t i = chunk * kChunk; i < end; ++i) ++counts[partitions[i]];
    }
  });
  uint32_t next = 0;
  for (std::size_t partition = 0; partition < kVoxelPartitions; ++partition) {
    first[partition] = next;
    for (std::size_t chunk = 0; chunk < chunks; ++chunk) {
      uint32_t& count = chunk_counts[chunk * kVoxelPartitions + partition];
      const uint32_t in_chunk = count;
      count = next;  // now where the chunk's first number of this map goes
      next += in_chunk;
    }
  }
  first[kVoxelPartitions] = next;
  order.resize(partitions.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks), [&](const tbb::blocked_range<std::size_t>& block) {
    for (std::size_t chunk = block.begin(); chunk < block.end(); ++chunk) {
      uint32_t* places = &chunk_counts[chunk * kVoxelPartitions];
      const std::size_t end = std::min(partitions.size(), (chunk + 1) * kChunk);
      for (std::size_t i = chunk * kChunk; i < end; ++i) order[places[partitions[i]]++] = uint32_t(i);
    }
  });
}

// The neighbourhood of a point is the block of 3 x 3 x 3 voxels around its
// voxel (in the newest keyframe's frame), 2 normal_radius_m wide: every point
// of a voxel shares it, so the plane is fitted once per voxel of the newest
// keyframe, from the voxels' moments joined about the centre voxel's centre,
// instead of once per point over its neighbours.
void LocalModel::computeModelNormals() {
  const double voxel_size = 2.0 * options_.normal_radius_m / 3.0;
  const float inverse_size = float(1.0 / voxel_size);
  Keyframe& newest = keyframes_.back();
  const Eigen::Isometry3d newest_from_odom = newest.odom_from_lidar.inverse();
  const auto keyOf = [&](const Eigen::Vector3f& point) {
    return VoxelKey(floorToInt(point.x() * inverse_size), floorToInt(point.y() * inverse_size),
                    floorToInt(point.z() * inverse_size));
  };
  const auto centreOf = [&](const VoxelKey& key) { return (key.cast<double>().array() + 0.5).matrix() * voxel_size; };

  // The finest level's points of every keyframe, in the newest one's frame,
  // summed per voxel; a run of points in one voxel (neighbouring pixels)
  // takes one look-up. The voxels are split among kVoxelPartitions maps by
  // their key, each summed on its own thread in the points' order, so that
  // every voxel's sums are the same whatever the threads.
  // The newest keyframe's own points stay as they are (exactly: their
  // voxels are looked up again below).
  moved_points_.clear();
  for (const Keyframe& keyframe : keyframes_) {
    const Eigen::Isometry3f newest_from_keyframe = &keyframe == &newest
                                                       ? Eigen::Isometry3f::Identity()
                                                       : (newest_from_odom * keyframe.odom_from_lidar).cast<float>();
    const std::vector<Eigen::Vector3f>& points = keyframe.levels.back().points;
    const std::size_t first = moved_points_.size();
    moved_points_.resize(first + points.size());
    key_of_point_.resize(first + points.size());
    partition_of_point_.resize(first + points.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        const std::size_t i = block.begin();
                        moveAndBin(points[i].data(), block.size(), newest_from_keyframe.matrix().data(), inverse_size,
                                   moved_points_[first + i].data(), key_of_point_[first + i].data(),
                                   &partition_of_point_[first + i]);
                      });
  }
  points_by_partition_.sort(partition_of_point_);
  tbb::parallel_for(std::size_t(0), kVoxelPartitions, [&](std::size_t partition) {
    VoxelMap& voxels = model_voxels_[partition];
    voxels.clear();
    VoxelMoments* moments = nullptr;  // valid until the next insertion, which looks up again
    VoxelKey last_key = VoxelKey::Zero();
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    const PartitionOrder& sorted = points_by_partition_;
    for (uint32_t n = sorted.first[partition]; n < sorted.first[partition + 1]; ++n) {
      const uint32_t i = sorted.order[n];
      const Eigen::Vector3f& moved = moved_points_[i];
      const VoxelKey& key = key_of_point_[i];
      if (!moments || key != last_key) {
        moments = &voxels[key];
        last_key = key;
        centre = centreOf(key);
      }
      const Eigen::Vector3d d = moved.cast<double>() - centre;
      moments->count += 1.0;
      moments->sum += d;
      // The lower triangle only: the plane fit reads no other.
      moments->outer(0, 0) += d.x() * d.x();
      moments->outer(1, 0) += d.y() * d.x();
      moments->outer(2, 0) += d.z() * d.x();
      moments->outer(1, 1) += d.y() * d.y();
      moments->outer(2, 1) += d.z() * d.y();
      moments->outer(2, 2) += d.z() * d.z();
    }
  });
  const auto findVoxel = [&](const VoxelKey& key) -> const VoxelMoments* {
    const std::size_t hash = LatticeKeyHash()(key);
    const VoxelMap& voxels = model_voxels_[partitionOfHash(hash)];
    const auto found = voxels.find(key, hash);
    return found == voxels.end() ? nullptr : &found->second;
  };
  // The newest keyframe's voxels (of every level's points) that hold points,
  // found map by map in parallel (a run of points in one voxel takes one
  // look-up); the finest level's voxels and maps are those its points were
  // summed in (the last keyframe's above). Which slot a voxel gets does not
  // change its plane.
  const std::size_t newest_first = moved_points_.size() - newest.levels.back().points.size();
  std::size_t newest_count = 0;
  for (const Level& level : newest.levels) newest_count += level.points.size();
  newest_keys_.resize(newest_count);
  newest_partitions_.resize(newest_count);
  slot_of_point_.resize(newest_count);
  std::size_t level_first = 0;
  for (const Level& level : newest.levels) {
    const bool finest = &level == &newest.levels.back();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, level.points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        for (std::size_t i = block.begin(); i < block.end(); ++i) {
                          if (finest) {
                            newest_keys_[level_first + i] = key_of_point_[newest_first + i];
                            newest_partitions_[level_first + i] = partition_of_point_[newest_first + i];
                          } else {
                            const VoxelKey key = keyOf(level.points[i]);
                            newest_keys_[level_first + i] = key;
                            newest_partitions_[level_first + i] = partitionOfHash(LatticeKeyHash()(key));
                          }
                        }
                      });
    level_first += level.points.size();
  }
  newest_by_partition_.sort(newest_partitions_);
  tbb::parallel_for(std::size_t(0), kVoxelPartitions, [&](std::size_t partition) {
    VoxelMap& voxels = model_voxels_[partition];
    std::vector<VoxelKey>& slots = newest_voxels_of_partition_[partition];
    slots.clear();
    const PartitionOrder& sorted = newest_by_partition_;
    VoxelKey last_key = VoxelKey::Zero();
    uint32_t slot = kNoVoxel;
    for (uint32_t n = sorted.first[partition]; n < sorted.first[partition + 1]; ++n) {
      const uint32_t i = sorted.order[n];
      const VoxelKey& key = newest_keys_[i];
      if (n == sorted.first[partition] || key != last_key) {
        last_key = key;
        const auto found = voxels.find(key);
        if (found == voxels.end()) {
          slot = kNoVoxel;
        } else {
          VoxelMoments& moments = found.value();
          if (moments.slot == kNoVoxel) {
            moments.slot = uint32_t(slots.size());
            slots.push_back(key);
          }
          slot = moments.slot;
        }
      }
      slot_of_point_[i] = slot;  // within the map's slots
    }
  });
  first_slot_[0] = 0;
  for (std::size_t partition = 0; partition < kVoxelPartitions; ++partition)
    first_slot_[partition + 1] = first_slot_[partition] + uint32_t(newest_voxels_of_partition_[partition].size());
  newest_voxels_.resize(first_slot_.back());
  for (std::size_t partition = 0; partition < kVoxelPartitions; ++partition)
    std::copy(newest_voxels_of_partition_[partition].begin(), newest_voxels_of_partition_[partition].end(),
              newest_voxels_.begin() + first_slot_[partition]);

  // Each of its voxels' plane over the block.
  const double min_span_squared = (kMinSpan * options_.normal_radius_m) * (kMinSpan * options_.normal_radius_m);
  const double max_thickness_squared = kMaxThickness * kMaxThickness;
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  slot_normals_.resize(newest_voxels_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, newest_voxels_.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& block) {
                      for (std::size_t v = block.begin(); v < block.end(); ++v) {
                        const VoxelKey& key = newest_voxels_[v];
                        // The block's moments about the centre voxel's centre: a
                        // neighbour's, about its own centre o away, shifted by o.
                        // With s' = s + n o: the sum of d' d'^T is outer + s' o^T + o s^T
                        // (its lower triangle only).
                        double count = 0.0;
                        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
                        Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
                        for (int dx = -1; dx <= 1; ++dx)
                          for (int dy = -1; dy <= 1; ++dy)
                            for (int dz = -1; dz <= 1; ++dz) {
                              const VoxelMoments* found = findVoxel(key + VoxelKey(dx, dy, dz));
                              if (!found) continue;
                              const VoxelMoments& other = *found;
                              const Eigen::Vector3d offset = Eigen::Vector3d(dx, dy, dz) * voxel_size;
                              const Eigen::Vector3d shifted = other.sum + other.count * offset;
                              count += other.count;
                              sum += shifted;
                              for (int a = 0; a < 3; ++a)
                                for (int b = 0; b <= a; ++b)
                                  outer(a, b) += other.outer(a, b) + shifted(a) * offset(b) + offset(a) * other.sum(b);
                            }
                        slot_normals_[v] = Eigen::Vector3f::Constant(kNaN);
                        if (count < 6.0) continue;
                        const Eigen::Vector3d mean = sum / count;
                        // Lower triangle (as the moments): computeDirect reads no other.
                        const Eigen::Matrix3d covariance = outer / count - mean * mean.transpose();
                        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
                        solver.computeDirect(covariance);
                        const Eigen::Vector3d eigenvalues = solver.eigenvalues();  // ascending
                        // A plane: spread in two directions (not one ring's line) and thin.
                        if (!(eigenvalues(1) >= min_span_squared) ||
                            !(eigenvalues(0) <= max_thickness_squared * eigenvalues(1)))
                          continue;
                        const Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
                        if (normal.allFinite()) slot_normals_[v] = normal;
                      }
                    });
  // Where the model has no plane (a far wall's rings a metre apart), the
  // keyframe's own normal, if any, stays.
  std::size_t first = 0;
  for (Level& level : newest.levels) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, level.points.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        for (std::size_t i = block.begin(); i < block.end(); ++i) {
                          const uint32_t slot = slot_of_point_[first + i];
                          if (slot == kNoVoxel) continue;
                          const Eigen::Vector3f& normal = slot_normals_[first_slot_[newest_partitions_[first + i]] + slot];
                          const Eigen::Vector3f& point = level.points[i];
                          if (normal.allFinite())
                            level.normals[i] = normal.dot(point) > 0.0f ? Eigen::Vector3f(-normal) : normal;
                        }
                      });
    first += level.points.size();
  }
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
  constexpr std::size_t kChunk = kRenderChunk;
  for (std::size_t l = 0; l < level_count; ++l) {
    const int s = keyframes_.back().levels[l].stride;
    VertexNormalMap& level = levels[l];
    level.stride = s;
    level.rows = (model.rows() + s - 1) / s;
    level.columns = (model.columns() + s - 1) / s;
    const std::size_t size = std::size_t(level.rows) * level.columns;
    std::vector<uint32_t>& nearest = nearest_[l];
    std::vector<uint32_t>& winner = winner_[l];
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
    first_chunk_.assign(keyframes_.size() + 1, 0);
    for (std::size_t k = 0; k < keyframes_.size(); ++k)
      first_chunk_[k + 1] = first_chunk_[k] + (keyframe(k).levels[l].points.size() + kChunk - 1) / kChunk;
    const std::size_t chunks = first_chunk_.back();
    const std::size_t lanes = std::max<std::size_t>(
        1, std::min(chunks, kLanesPerThread * std::size_t(tbb::this_task_arena::max_concurrency())));
    // Lane n takes the chunks [lane_first(n), lane_first(n + 1)), so its
    // points' numbers all come before lane n + 1's.
    const auto lane_first = [&](std::size_t n) { return chunks * n / lanes; };
    // The number of chunk c's first point (all points' count for c = chunks).
    const auto first_number = [&](std::size_t c) {
      std::size_t k = 0;
      while (k < keyframes_.size() && c >= first_chunk_[k + 1]) ++k;
      return k == keyframes_.size() ? first_point_.back() : first_point_[k] + (c - first_chunk_[k]) * kChunk;
    };
    lane_buffers_.resize(std::max(lane_buffers_.size(), lanes));
    const auto each_lane = [&](auto&& body) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lanes, 1), [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t n = range.begin(); n < range.end(); ++n) body(n, lane_buffers_[n]);
      });
    };
    // Each pixel's minimum over the lanes' buffers.
    const auto merge_lanes = [&](std::vector<uint32_t>& merged) {
      merged.resize(size);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, size, 8192), [&](const tbb::blocked_range<std::size_t>& block) {
        for (std::size_t p = block.begin(); p < block.end(); ++p) {
          uint32_t least = lane_buffers_[0][p];
          for (std::size_t n = 1; n < lanes; ++n) least = std::min(least, lane_buffers_[n][p]);
          merged[p] = least;
        }
      });
    };

    // Pass 1: every point's pixel and range, and each pixel's nearest range.
    // Points without a normal take part in the z-buffer (they occlude) but
    // cannot win a pixel: they get no pixel for pass 2.
    // All keyframes' chunks in one loop (the coarse levels have few points each).
    each_lane([&](std::size_t n, std::vector<uint32_t>& lane_nearest) {
      lane_nearest.assign(size, kNoRange);
      uint32_t* buffer = lane_nearest.data();
      ChunkBuffers chunk;
      std::size_t k = 0;
      for (std::size_t c = lane_first(n); c < lane_first(n + 1); ++c) {
        while (c >= first_chunk_[k + 1]) ++k;
        const Level& points = *level_points_[k];
        const std::size_t begin = (c - first_chunk_[k]) * kChunk;
        const std::size_t count = std::min(kChunk, points.points.size() - begin);
        const std::size_t first = first_point_[k];
        if (count == 0) continue;  // never; tells the compiler the arrays are set before projectMany
        transformToArrays(points.points[begin].data(), count, view_from_keyframe_[k].matrix().data(), chunk.x,
                          chunk.y, chunk.z);
        model.projectMany(chunk.x, chunk.y, chunk.z, count, chunk.pixels, chunk.hits);
        for (std::size_t i = 0; i < count; ++i) {
          const std::size_t number = first + begin + i;
          if (!chunk.hits[i]) {
            pixel_of_point_[number] = kNoPoint;
            continue;
          }
          const uint32_t pixel = uint32_t(pixel_tables_.index(chunk.pixels[i]));
          const bool has_normal = std::isfinite(points.normals[begin + i].x());
          pixel_of_point_[number] = has_normal ? pixel : kNoPoint;
          range_of_point_[number] = chunk.pixels[i].range;
          buffer[pixel] = std::min(buffer[pixel], rangeBits(chunk.pixels[i].range));
        }
      }
    });
    merge_lanes(nearest);
    // Pass 2: of the points on the nearest surface, the newest keyframe's
    // (the least number). The nearest point itself would be biased towards
    // the sensor by the noise: the least of several noisy ranges of one surface.
    each_lane([&](std::size_t n, std::vector<uint32_t>& lane_winner) {
      lane_winner.assign(size, kNoPoint);
      uint32_t* buffer = lane_winner.data();
      for (std::size_t number = first_number(lane_first(n)), end = first_number(lane_first(n + 1)); number < end;
           ++number) {
        const uint32_t pixel = pixel_of_point_[number];
        if (pixel == kNoPoint) continue;
        const float range = range_of_point_[number];
        float front;
        std::memcpy(&front, &nearest[pixel], sizeof front);
        if (range <= front + std::max(kSurfaceThickness_m, kSurfaceThicknessShare * front))
          buffer[pixel] = std::min(buffer[pixel], uint32_t(number));
      }
    });
    merge_lanes(winner);

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
