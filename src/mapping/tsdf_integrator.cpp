#include "range_image_mapping/mapping/tsdf_integrator.h"

#include "number_text.h"
#include "range_image_mapping/registration/normal_map.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tsl/robin_set.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

namespace range_image_mapping::mapping {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Rows of pixels per activation task: enough work to amortise the task.
constexpr int kActivationRowsPerTask = 4;
// Incidence weighting: a grazing sample still counts a little, and so does a
// pixel on a depth edge (no normal), rather than vanishing.
constexpr float kMinimumIncidenceWeight = 0.1f;
// Below this weight a deintegrated voxel counts as unobserved (float sums of
// the same weights rarely cancel to exactly 0).
constexpr float kUnobservedWeight = 1e-4f;
// Poses whose rotation is off orthonormal by more than this are rejected.
constexpr double kOrthonormalTolerance = 1e-3;
// Projections of a voxel into the moving sensor before it counts as not
// settling (projectIntoMovingSensor).
constexpr int kMotionRefinements = 3;

using BlockSet = tsl::robin_set<BlockKey, BlockKeyHash>;

// Calls visit(key) for every block the segment a -> b passes through, a and b
// in block units (world / block size): a 3D DDA (Amanatides & Woo) over the
// block lattice, so no block is skipped however the segment is oriented.
template <typename Visit>
void visitBlocksOnSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b, Visit&& visit) {
  BlockKey cell(int(std::floor(a.x())), int(std::floor(a.y())), int(std::floor(a.z())));
  const BlockKey last(int(std::floor(b.x())), int(std::floor(b.y())), int(std::floor(b.z())));
  const Eigen::Vector3d direction = b - a;
  Eigen::Vector3i step;
  Eigen::Vector3d next_crossing, crossing_interval;  // in units of the segment (0 at a, 1 at b)
  for (int axis = 0; axis < 3; ++axis) {
    const double d = direction[axis];
    step[axis] = d > 0 ? 1 : (d < 0 ? -1 : 0);
    if (step[axis] == 0) {
      next_crossing[axis] = crossing_interval[axis] = std::numeric_limits<double>::infinity();
    } else {
      const double border = cell[axis] + (step[axis] > 0 ? 1.0 : 0.0);
      next_crossing[axis] = (border - a[axis]) / d;
      crossing_interval[axis] = 1.0 / std::abs(d);
    }
  }
  visit(cell);
  // As many steps as lattice borders between the end cells: rounding cannot
  // make the walk run away.
  const int steps = (last - cell).cwiseAbs().sum();
  for (int n = 0; n < steps; ++n) {
    int axis;
    next_crossing.minCoeff(&axis);
    cell[axis] += step[axis];
    next_crossing[axis] += crossing_interval[axis];
    visit(cell);
  }
}

// One voxel's running weighted average (paper eq. 10), in both directions:
// `add` puts a sample in, otherwise one put in before is taken out.
struct VoxelUpdate {
  float max_weight;
  bool add;

  // Intensity (when given) is averaged with the same weights as the SDF.
  inline void apply(float& sdf, float& weight, float sample, float sample_weight, float* intensity,
                    float sample_intensity) const {
    if (add) {
      const float total = weight + sample_weight;
      sdf = (sdf * weight + sample * sample_weight) / total;
      if (intensity) *intensity = (*intensity * weight + sample_intensity * sample_weight) / total;
      weight = std::min(total, max_weight);
      return;
    }
    const float total = weight - sample_weight;
    if (total <= kUnobservedWeight) {
      sdf = 0.0f;
      weight = 0.0f;
      if (intensity) *intensity = 0.0f;
      return;
    }
    sdf = (sdf * weight - sample * sample_weight) / total;
    if (intensity) *intensity = (*intensity * weight - sample_intensity * sample_weight) / total;
    weight = total;
  }
};

// Voxel positions and their projections for one block, reused per thread.
struct BlockBuffers {
  std::vector<Eigen::Vector3f> points, moved_points;
  std::vector<ProjectedPixel> pixels;
  std::vector<uint8_t> hits;
  // Motion refinement: the column whose motion placed each voxel, and the
  // voxels still to refine, packed for projectMany.
  std::vector<int> motion_columns;
  std::vector<uint32_t> pending;
  std::vector<ProjectedPixel> pending_pixels;
  std::vector<uint8_t> pending_hits;
  void resize(std::size_t voxels) {
    if (points.size() == voxels) return;
    points.resize(voxels);
    moved_points.resize(voxels);
    pixels.resize(voxels);
    hits.resize(voxels);
    motion_columns.resize(voxels);
    pending.resize(voxels);
    pending_pixels.resize(voxels);
    pending_hits.resize(voxels);
  }
};

void requireFiniteOption(double value, const char* field) {
  if (!std::isfinite(value)) throw MappingError(std::string(field) + " must be finite, got " + numberText(value));
}

}  // namespace

void TsdfIntegratorOptions::validate(const VoxelBlockGridOptions& grid) const {
  grid.validate();
  requireFiniteOption(truncation_m, "truncation_m");
  if (truncation_m < 0.0)
    throw MappingError("truncation_m must be >= 0 (0 = 3 voxels), got " + numberText(truncation_m));
  const double truncation = truncationFor(grid);
  if (truncation < grid.voxel_size_m || truncation > 100.0 * grid.voxel_size_m)
    throw MappingError("truncation_m must be within [1, 100] voxels (" + numberText(grid.voxel_size_m) +
                       " m each), got " + numberText(truncation));
  requireFiniteOption(min_range_m, "min_range_m");
  requireFiniteOption(max_range_m, "max_range_m");
  if (min_range_m < 0.0) throw MappingError("min_range_m must be >= 0, got " + numberText(min_range_m));
  if (!(max_range_m > min_range_m))
    throw MappingError("max_range_m must exceed min_range_m (" + numberText(min_range_m) + "), got " +
                       numberText(max_range_m));
  if (point_stride < 1) throw MappingError("point_stride must be >= 1, got " + std::to_string(point_stride));
  if (!(max_weight > 0.0f) || !std::isfinite(max_weight))
    throw MappingError("max_weight must be positive and finite, got " + numberText(max_weight));
  if (range_weighting && !(range_weighting_start_m > 0.0 && std::isfinite(range_weighting_start_m)))
    throw MappingError("range_weighting_start_m must be positive and finite, got " +
                       numberText(range_weighting_start_m));
}

struct TsdfIntegrator::Workspace {
  tbb::enumerable_thread_specific<BlockSet> thread_blocks;
  tbb::enumerable_thread_specific<std::size_t> thread_points_used{0};
  tbb::enumerable_thread_specific<BlockBuffers> thread_buffers;
  BlockSet merged_blocks;
  std::vector<uint8_t> created;            // per touched block
  std::vector<uint32_t> voxels_updated;    // per touched block
  std::vector<ColumnMotion> column_motion_inverse;  // scan-time frame -> column-time frame
  std::vector<float> column_time;                   // seconds after the scan time
  std::vector<float> sample_weight;        // per pixel; empty: every sample weighs 1
  registration::VertexNormalMap normals;   // for incidence weighting
};

namespace {

// The sensor's motion within a sweep, per column (scan_motion.h).
struct SweepMotion {
  const std::vector<ColumnMotion>& inverse;  // scan-time frame -> column-time frame
  const std::vector<float>& time;            // column time after the scan time, s
  // A pixel measured this close in time to the motion that placed the voxel
  // is close enough (see motionTimeTolerance).
  float tolerance_s;

  Eigen::Vector3f toColumnFrame(int column, const Eigen::Vector3f& point) const {
    return inverse[column].leftCols<3>() * point + inverse[column].col(3);
  }
  bool settled(int motion_column, int measured_column) const {
    return std::abs(time[measured_column] - time[motion_column]) <= tolerance_s;
  }
};

// How far in time the motion used for a voxel may be from its pixel's
// column: the range then errs by at most time * |v| <= voxel / 50, and a turn
// shifts the voxel by at most a quarter of a column (rotation about the
// origin leaves ranges alone). Never below two column periods, which the
// discrete column cannot resolve anyway.
float motionTimeTolerance(const Twist& twist, double voxel_size, int columns, float column_period_s) {
  constexpr double kRangeErrorInVoxels = 1.0 / 50.0;
  constexpr double kShiftInColumns = 0.25;
  constexpr float kLeastColumns = 2.0f;
  double tolerance = std::numeric_limits<double>::infinity();
  const double speed = twist.tail<3>().norm(), turn_rate = twist.head<3>().norm();
  if (speed > 0.0) tolerance = std::min(tolerance, kRangeErrorInVoxels * voxel_size / speed);
  if (turn_rate > 0.0) tolerance = std::min(tolerance, kShiftInColumns * (2.0 * M_PI / columns) / turn_rate);
  return std::max(float(tolerance), kLeastColumns * column_period_s);
}

// The column that saw a point of the scan-time frame from the moving sensor:
// the fixed point of  u -> column of Pi(motion[u]^-1 x), the point as the
// sensor saw it when column u fired. -1 if the point leaves the field of view.
int columnSeenFromMovingSensor(const LidarModel& model, const SweepMotion& motion, const Eigen::Vector3f& point) {
  const std::optional<ProjectedPixel> start = model.project(point);
  if (!start) return -1;
  int column = start->column;
  for (int pass = 0; pass < kMotionRefinements; ++pass) {
    const std::optional<ProjectedPixel> moved = model.project(motion.toColumnFrame(column, point));
    if (!moved) return -1;
    const bool settled = motion.settled(column, moved->column);
    column = moved->column;
    if (settled) break;
  }
  return column;
}

// Pi of a block's voxels into the moving sensor: each voxel as the sensor
// saw it when the column that measured it fired (the fixed point above, for
// every voxel). All voxels start with the block centre's column; those whose
// pixel was measured too far in time from the motion used are moved again
// with their own column's (different rows fire at columns up to 30 apart on
// an OS0). Voxels that do not settle lie where the sweep's start and end
// overlap or leave a gap (the seam): they miss this scan rather than being
// averaged with the wrong sensor position.
void projectIntoMovingSensor(const LidarModel& model, const SweepMotion& motion, const Eigen::Vector3f& block_centre,
                             std::size_t voxels, BlockBuffers& buffers) {
  const int centre_column = columnSeenFromMovingSensor(model, motion, block_centre);
  if (centre_column >= 0) {
    for (std::size_t i = 0; i < voxels; ++i) {
      buffers.pixels[i].column = centre_column;
      buffers.hits[i] = 1;
    }
  } else {  // the centre is outside the field of view: start from the scan-time projection
    model.projectMany(buffers.points.data(), voxels, buffers.pixels.data(), buffers.hits.data());
  }
  std::size_t pending = 0;
  for (std::size_t i = 0; i < voxels; ++i)
    if (buffers.hits[i]) buffers.pending[pending++] = uint32_t(i);
  for (int pass = 0; pass < kMotionRefinements && pending > 0; ++pass) {
    for (std::size_t n = 0; n < pending; ++n) {
      const uint32_t i = buffers.pending[n];
      buffers.motion_columns[i] = buffers.pixels[i].column;
      buffers.moved_points[n] = motion.toColumnFrame(buffers.motion_columns[i], buffers.points[i]);
    }
    model.projectMany(buffers.moved_points.data(), pending, buffers.pending_pixels.data(),
                      buffers.pending_hits.data());
    std::size_t unsettled = 0;
    for (std::size_t n = 0; n < pending; ++n) {
      const uint32_t i = buffers.pending[n];
      buffers.hits[i] = buffers.pending_hits[n];
      if (!buffers.hits[i]) continue;
      buffers.pixels[i] = buffers.pending_pixels[n];
      if (!motion.settled(buffers.motion_columns[i], buffers.pixels[i].column)) buffers.pending[unsettled++] = i;
    }
    pending = unsettled;
  }
  for (std::size_t n = 0; n < pending; ++n) buffers.hits[buffers.pending[n]] = 0;
}

}  // namespace

TsdfIntegrator::TsdfIntegrator(TsdfIntegratorOptions options)
    : options_(options), workspace_(std::make_unique<Workspace>()) {}
TsdfIntegrator::~TsdfIntegrator() = default;
TsdfIntegrator::TsdfIntegrator(TsdfIntegrator&&) noexcept = default;
TsdfIntegrator& TsdfIntegrator::operator=(TsdfIntegrator&&) noexcept = default;

IntegrationStatistics TsdfIntegrator::integrate(VoxelBlockGrid& grid, const RangeImage& scan,
                                                const ScanPose& pose) {
  return update(grid, scan, pose, 1.0f);
}

IntegrationStatistics TsdfIntegrator::deintegrate(VoxelBlockGrid& grid, const RangeImage& scan,
                                                  const ScanPose& pose) {
  return update(grid, scan, pose, -1.0f);
}

void TsdfIntegrator::validate(const VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose) const {
  const TsdfIntegratorOptions& options = options_;
  options.validate(grid.options());
  if (!scan.model) throw MappingError("scan has no sensor model");
  if (scan.column_order != ColumnOrder::kStaggered)
    throw MappingError("scan is destaggered; integration needs the staggered image (column = measurement id)");
  const std::size_t pixels = std::size_t(scan.rows()) * scan.columns();
  if (scan.range.size() != pixels)
    throw MappingError("scan has " + std::to_string(scan.range.size()) + " ranges, its model needs " +
                       std::to_string(pixels));
  if (!scan.intensity.empty() && scan.intensity.size() != pixels)
    throw MappingError("scan has " + std::to_string(scan.intensity.size()) + " intensities, expected 0 or " +
                       std::to_string(pixels));
  if (!pose.world_from_lidar.matrix().allFinite()) throw MappingError("scan pose is not finite");
  if (!pose.twist.allFinite()) throw MappingError("scan twist is not finite");
  const Eigen::Matrix3d rotation = pose.world_from_lidar.linear();
  const double orthonormal_error = (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).norm();
  if (orthonormal_error > kOrthonormalTolerance || rotation.determinant() < 0.0)
    throw MappingError("scan pose rotation is not a rotation (|R^T R - I| = " + numberText(orthonormal_error) +
                       ", det " + numberText(rotation.determinant()) + ")");
  const double reach = pose.world_from_lidar.translation().norm() + options.max_range_m +
                       options.truncationFor(grid.options()) + grid.blockSize();
  if (reach / grid.voxelSize() >= VoxelBlockGrid::kLargestLatticeIndex)
    throw MappingError("scan pose translation " + numberText(pose.world_from_lidar.translation().norm()) +
                       " m is beyond what the voxel grid can index at " + numberText(grid.voxelSize()) +
                       " m voxels");
}

IntegrationStatistics TsdfIntegrator::update(VoxelBlockGrid& grid, const RangeImage& scan,
                                             const ScanPose& pose, float sign) {
  validate(grid, scan, pose);
  Workspace& work = *workspace_;
  IntegrationStatistics statistics;
  const uint64_t generation = grid.nextGeneration();
  const bool adding = sign > 0.0f;
  const LidarModel& model = *scan.model;
  const int rows = scan.rows(), columns = scan.columns();
  const float truncation = static_cast<float>(options_.truncationFor(grid.options()));
  const float min_range = static_cast<float>(options_.min_range_m);
  const float max_range = static_cast<float>(options_.max_range_m);

  // Motion within the sweep: each column seen from where the sensor was when
  // it fired (scan_motion.h); none for a zero twist or without column times.
  const bool moving = computeColumnMotion(scan, scanTime(scan), pose.twist, column_motion_);
  float time_tolerance_s = 0.0f;
  if (moving) {
    work.column_motion_inverse.resize(columns);
    work.column_time.resize(columns);
    const uint64_t scan_time = scanTime(scan);
    float earliest = 0.0f, latest = 0.0f;
    int timed_columns = 0;
    for (int u = 0; u < columns; ++u) {
      const Eigen::Matrix3f rotation_t = column_motion_[u].leftCols<3>().transpose();
      work.column_motion_inverse[u] << rotation_t, -rotation_t * column_motion_[u].col(3);
      const uint64_t time = scan.column_timestamp_ns[u];
      work.column_time[u] = time == 0 ? 0.0f : float((double(time) - double(scan_time)) * 1e-9);
      earliest = std::min(earliest, work.column_time[u]);
      latest = std::max(latest, work.column_time[u]);
      timed_columns += time != 0;
    }
    // Columns outside the sensor's column window have no time.
    const float column_period_s = (latest - earliest) / float(std::max(timed_columns - 1, 1));
    time_tolerance_s = motionTimeTolerance(pose.twist, grid.voxelSize(), columns, column_period_s);
  }

  // Optional per-pixel sample weights.
  const bool weighted = options_.range_weighting || options_.incidence_weighting;
  if (weighted) {
    work.sample_weight.assign(scan.range.size(), 1.0f);
    if (options_.incidence_weighting)
      registration::computeVertexNormalMap(scan, 1, registration::NormalMapOptions{}, work.normals);
    const float falloff_start = static_cast<float>(options_.range_weighting_start_m);
    tbb::parallel_for(0, rows, [&](int v) {
      for (int u = 0; u < columns; ++u) {
        const std::size_t i = scan.index(v, u);
        const float range = scan.range[i];
        if (!isValidRange(range)) continue;
        float weight = 1.0f;
        // Range noise and beam footprint grow with range: fade far samples ~1/r^2.
        if (options_.range_weighting && range > falloff_start)
          weight *= (falloff_start / range) * (falloff_start / range);
        if (options_.incidence_weighting) {
          // Normals face the sensor, so cos(incidence) = -n . ray direction.
          const float cosine = -work.normals.normals[i].dot(model.direction(u, v));
          weight *= std::isfinite(cosine) ? std::max(cosine, kMinimumIncidenceWeight) : kMinimumIncidenceWeight;
        }
        work.sample_weight[i] = weight;
      }
    });
  }

  // 1. Activation: the blocks the beam crosses within the truncation band
  // around each return (paper section 4.2: activate blocks near each point).
  const Clock::time_point activation_start = Clock::now();
  const double block_size = grid.blockSize();
  const Eigen::Isometry3d world_from_lidar = pose.world_from_lidar;
  const int stride = options_.point_stride;
  const int strided_rows = (rows + stride - 1) / stride;
  for (BlockSet& blocks : work.thread_blocks) blocks.clear();
  for (std::size_t& count : work.thread_points_used) count = 0;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, strided_rows, kActivationRowsPerTask), [&](const tbb::blocked_range<int>& range) {
        BlockSet& blocks = work.thread_blocks.local();
        std::size_t& used = work.thread_points_used.local();
        BlockKey previous(std::numeric_limits<int>::min(), 0, 0);
        const auto insert = [&](const BlockKey& key) {
          // Neighbouring pixels mostly cross the same blocks: skip the hash then.
          if (key == previous) return;
          previous = key;
          blocks.insert(key);
        };
        for (int strided_row = range.begin(); strided_row != range.end(); ++strided_row) {
          const int v = strided_row * stride;
          for (int u = 0; u < columns; u += stride) {
            const float r = scan.range[scan.index(v, u)];
            if (!(r >= min_range && r <= max_range)) continue;  // also NaN
            ++used;
            Eigen::Vector3f near_point = model.unproject(u, v, std::max(r - truncation, 0.0f));
            Eigen::Vector3f far_point = model.unproject(u, v, r + truncation);
            if (moving) {
              const ColumnMotion& motion = column_motion_[u];
              near_point = motion.leftCols<3>() * near_point + motion.col(3);
              far_point = motion.leftCols<3>() * far_point + motion.col(3);
            }
            visitBlocksOnSegment((world_from_lidar * near_point.cast<double>()) / block_size,
                                 (world_from_lidar * far_point.cast<double>()) / block_size, insert);
          }
        }
      });
  statistics.points_used = work.thread_points_used.combine(std::plus<std::size_t>());
  work.merged_blocks.clear();
  for (const BlockSet& blocks : work.thread_blocks) work.merged_blocks.insert(blocks.begin(), blocks.end());
  touched_keys_.assign(work.merged_blocks.begin(), work.merged_blocks.end());
  // Nearest blocks first, so that a memory budget running out keeps the
  // sensor's surroundings; ties broken by key so that the order (and the
  // grid's pool slots) does not depend on the threads.
  const Eigen::Vector3d sensor_in_blocks = world_from_lidar.translation() / block_size -
                                           Eigen::Vector3d::Constant(0.5);
  std::sort(touched_keys_.begin(), touched_keys_.end(), [&](const BlockKey& a, const BlockKey& b) {
    const double distance_a = (a.cast<double>() - sensor_in_blocks).squaredNorm();
    const double distance_b = (b.cast<double>() - sensor_in_blocks).squaredNorm();
    if (distance_a != distance_b) return distance_a < distance_b;
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  touched_blocks_.clear();
  work.created.clear();
  for (const BlockKey& key : touched_keys_) {
    bool created = false;
    VoxelBlock* block = adding ? grid.activate(key, &created) : grid.find(key);
    if (block == nullptr) {
      // Removing: a block that is not there holds nothing to remove.
      if (adding) ++statistics.blocks_refused;
      continue;
    }
    touched_blocks_.push_back(block);
    work.created.push_back(created);
  }
  statistics.activation_seconds = secondsSince(activation_start);

  // 2. Integration: every voxel of every touched block projected with Pi
  // (eq. 8), d = Omega(u, v) - r (eq. 9), averaged (eq. 10). One block per
  // task, so no two threads write one voxel.
  const Clock::time_point integration_start = Clock::now();
  const Eigen::Isometry3d lidar_from_world = world_from_lidar.inverse();
  const Eigen::Matrix3f lattice_steps = (lidar_from_world.linear() * grid.voxelSize()).cast<float>();
  const int edge = grid.blockEdge();
  const std::size_t voxels = static_cast<std::size_t>(grid.voxelsPerBlock());
  const bool with_intensity = grid.options().store_intensity && scan.intensity.size() == scan.range.size();
  const VoxelUpdate voxel_update{options_.max_weight, adding};
  const SweepMotion sweep_motion{work.column_motion_inverse, work.column_time, time_tolerance_s};
  work.voxels_updated.assign(touched_blocks_.size(), 0);
  const float* ranges = scan.range.data();
  const float* intensities = with_intensity ? scan.intensity.data() : nullptr;
  const float* sample_weights = weighted ? work.sample_weight.data() : nullptr;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, touched_blocks_.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    BlockBuffers& buffers = work.thread_buffers.local();
    buffers.resize(voxels);
    for (std::size_t b = range.begin(); b != range.end(); ++b) {
      VoxelBlock& block = *touched_blocks_[b];
      // Voxel positions in the lidar frame, relative to the block's first
      // voxel in double so that floats keep millimetres far from the origin.
      const Eigen::Vector3f first =
          (lidar_from_world * grid.voxelPosition(block.key, 0, 0, 0)).cast<float>();
      std::size_t n = 0;
      for (int k = 0; k < edge; ++k)
        for (int j = 0; j < edge; ++j) {
          const Eigen::Vector3f row_start = first + lattice_steps.col(1) * float(j) + lattice_steps.col(2) * float(k);
          for (int i = 0; i < edge; ++i) buffers.points[n++] = row_start + lattice_steps.col(0) * float(i);
        }
      if (moving) {
        const Eigen::Vector3f centre =
            first + lattice_steps * Eigen::Vector3f::Constant(0.5f * float(edge - 1));
        projectIntoMovingSensor(model, sweep_motion, centre, voxels, buffers);
      } else {
        model.projectMany(buffers.points.data(), voxels, buffers.pixels.data(), buffers.hits.data());
      }
      // Raw pointers: the compiler cannot prove the vectors' members unchanged
      // by the stores below and would reload them for every voxel.
      const uint8_t* hits = buffers.hits.data();
      const ProjectedPixel* pixels = buffers.pixels.data();
      float* sdf = block.sdf.data();
      float* weight = block.weight.data();
      float* intensity = with_intensity ? block.intensity.data() : nullptr;
      uint32_t updated = 0;
      for (std::size_t i = 0; i < voxels; ++i) {
        if (!hits[i]) continue;
        const std::size_t p = std::size_t(pixels[i].row) * columns + pixels[i].column;
        const float measured = ranges[p];
        if (!(measured >= min_range && measured <= max_range)) continue;  // also NaN
        const float distance = measured - pixels[i].range;
        if (distance < -truncation) continue;  // occluded: behind the surface
        voxel_update.apply(sdf[i], weight[i], std::min(distance, truncation),
                           sample_weights ? sample_weights[p] : 1.0f, intensity ? intensity + i : nullptr,
                           intensity ? intensities[p] : 0.0f);
        ++updated;
      }
      work.voxels_updated[b] = updated;
    }
  });

  // Bookkeeping: changed blocks carry this generation; blocks that hold no
  // observation any more (created for nothing, or emptied by removal) go.
  statistics.blocks_touched = touched_blocks_.size();
  for (std::size_t b = 0; b < touched_blocks_.size(); ++b) {
    VoxelBlock& block = *touched_blocks_[b];
    statistics.voxels_updated += work.voxels_updated[b];
    const bool may_be_empty = work.created[b] || !adding;
    if (may_be_empty &&
        std::none_of(block.weight.begin(), block.weight.end(), [](float w) { return w > 0.0f; })) {
      grid.remove(block.key);
      if (!adding) ++statistics.blocks_removed;
      continue;
    }
    if (work.created[b]) ++statistics.blocks_created;
    if (work.voxels_updated[b] > 0) block.changed_generation = generation;
  }
  statistics.integration_seconds = secondsSince(integration_start);
  return statistics;
}

}  // namespace range_image_mapping::mapping
