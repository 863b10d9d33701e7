#include "range_image_mapping/mapping/tsdf_integrator.h"

#include "number_text.h"
#include "range_image_mapping/normal_map.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tsl/robin_map.h>

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
// Point-to-plane: incidence cosines below this count as this (the normal map
// gives no normal to surfaces seen more edge-on than that anyway).
constexpr float kSmallestPlaneCosine = 1e-3f;
// Point-to-plane beyond a pixel's truncation band: the plane counts where the
// return under the voxel lies this close to it (in voxels). Half a voxel:
// above the noise and the normal's error over a few metres, below a curb.
// (Measured on outdoor_car: 1 voxel let roofs and facade tops run on past
// their edges, precision at 3 voxels 0.994 against 0.998.)
constexpr double kPlaneSeenToleranceVoxels = 0.5;
// Point-to-plane: cells are activated within the truncation plus this share
// of a pixel's footprint along the ray, as far as voxels take the plane
// distance: cells are thin across the ray and need the whole reach.
constexpr float kPlaneActivationShare = 1.0f;
// Cells are activated this many voxels farther in front of each return than
// the truncation band (or the plane's reach): the free space just in front
// of a surface, which makes the lattice cubes on its far side observed
// (fewer voxels lose recall; the README's VDBFusion section has the figures).
constexpr double kFreeSpaceActivationVoxels = 4.0;
// Poses whose rotation is off orthonormal by more than this are rejected.
constexpr double kOrthonormalTolerance = 1e-3;
// Projections of a voxel into the moving sensor before it counts as not
// settling (projectIntoMovingSensor).
constexpr int kMotionRefinements = 3;

// Activation works in cells of kActivationCellVoxels^3 voxels (one bit each
// in a block's mask, so at most 4 x 4 x 4 cells a block): a block's voxels
// are projected only in the cells a return's band crossed, and not in the
// rest of the block (under the ground, behind a wall), which no pixel writes
// or only as far free space.
constexpr int kActivationCellVoxels = 4;
// A cell also selects the voxel layer next to it in the cells on either
// side on each axis: the lattice cubes around a surface in the cell are then
// whole, and so are the ones across its faces.
using CellMask = uint64_t;
using BlockCells = tsl::robin_map<BlockKey, CellMask, BlockKeyHash>;

struct ActivationCells {
  int block_edge = 0;
  int cell_voxels = 1;   // voxels per cell edge
  int cells_per_edge = 1;  // 1, 2 or 4
  int shift = 0;           // log2(cells_per_edge): cell -> block by arithmetic shift
  // Per voxel of a block: the cells whose activation selects it, and its
  // lattice coordinates i, j, k as floats.
  std::vector<CellMask> selecting_cells;
  std::vector<float> lattice_i, lattice_j, lattice_k;
  // Per row of voxels along the block's x axis (index j + edge * k): the
  // cells that select any voxel of the row, so that a row no activated cell
  // selects is passed over whole.
  std::vector<CellMask> row_selecting_cells;
  // With at most 8 cells a block (2 x 2 x 2), every activated mask's
  // selection is tabled: its voxel indices and lattice coordinates, in
  // index order, start at selection_start[mask] (selection_start[mask + 1]
  // ends them). Empty with more cells.
  std::vector<uint32_t> selection_start, selection_index;
  std::vector<float> selection_i, selection_j, selection_k;

  void configure(int edge) {
    if (edge == block_edge) return;
    block_edge = edge;
    cell_voxels = std::max(kActivationCellVoxels, edge / 4);
    cells_per_edge = std::max(edge / cell_voxels, 1);
    cell_voxels = edge / cells_per_edge;
    shift = cells_per_edge == 4 ? 2 : (cells_per_edge == 2 ? 1 : 0);
    selecting_cells.assign(std::size_t(edge) * edge * edge, 0);
    lattice_i.resize(selecting_cells.size());
    lattice_j.resize(selecting_cells.size());
    lattice_k.resize(selecting_cells.size());
    row_selecting_cells.assign(std::size_t(edge) * edge, 0);
    // The cells of one axis coordinate: its own, and the one below for the
    // first layer of a cell.
    const auto cellsOf = [&](int x, int* cells) {
      cells[0] = cells[1] = cells[2] = x / cell_voxels;
      if (x % cell_voxels == 0 && x > 0) cells[1] = x / cell_voxels - 1;
      if (x % cell_voxels == cell_voxels - 1 && x + 1 < edge) cells[2] = x / cell_voxels + 1;
    };
    std::size_t v = 0;
    for (int k = 0; k < edge; ++k)
      for (int j = 0; j < edge; ++j)
        for (int i = 0; i < edge; ++i, ++v) {
          int ci[3], cj[3], ck[3];
          cellsOf(i, ci);
          cellsOf(j, cj);
          cellsOf(k, ck);
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b)
              for (int c = 0; c < 3; ++c)
                selecting_cells[v] |= CellMask(1) << (ci[a] + cells_per_edge * (cj[b] + cells_per_edge * ck[c]));
          lattice_i[v] = float(i);
          lattice_j[v] = float(j);
          lattice_k[v] = float(k);
          row_selecting_cells[v / edge] |= selecting_cells[v];
        }
    selection_start.clear();
    selection_index.clear();
    selection_i.clear();
    selection_j.clear();
    selection_k.clear();
    if (cells_per_edge <= 2) {
      constexpr CellMask kMasks = 256;
      selection_start.reserve(kMasks + 1);
      for (CellMask mask = 0; mask < kMasks; ++mask) {
        selection_start.push_back(uint32_t(selection_index.size()));
        for (std::size_t voxel = 0; voxel < selecting_cells.size(); ++voxel) {
          if (!(selecting_cells[voxel] & mask)) continue;
          selection_index.push_back(uint32_t(voxel));
          selection_i.push_back(lattice_i[voxel]);
          selection_j.push_back(lattice_j[voxel]);
          selection_k.push_back(lattice_k[voxel]);
        }
      }
      selection_start.push_back(uint32_t(selection_index.size()));
    }
  }
  double cellSize(double voxel_size) const { return voxel_size * cell_voxels; }
};

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

// What point-to-plane integration reads of a pixel, together (the voxel
// loop's gathers are cache misses): its range, the plane n . x = offset
// through its point with its normal (n facing the sensor), and how far
// behind the point along the ray (reach) a voxel may be and still take the
// plane distance. reach is NaN where the pixel has no normal.
struct PixelPlane {
  Eigen::Vector3f normal;
  float offset;
  float range;
  float reach;
  float distance(const Eigen::Vector3f& x) const { return normal.dot(x) - offset; }
};

// Eq. 10 for the voxels of one block, and what the mesh sees of the change:
// observed (weight > 0, >= the mesh's minimum), the sign, and the value.
struct BlockWriter {
  float* sdf;
  float* weight;
  float* intensity;               // nullptr: no intensity
  const float* sample_weights;    // per pixel; nullptr: every sample weighs 1
  const float* pixel_intensities;
  VoxelUpdate voxel_update;
  float truncation, mesh_min_weight, free_space_weight;
  uint32_t updated = 0;
  float drift = 0.0f;
  bool topology = false;

  [[gnu::always_inline]] inline void operator()(std::size_t i, std::size_t p, float distance) {
    const float old_sdf = sdf[i], old_weight = weight[i];
    float sample_weight = sample_weights ? sample_weights[p] : 1.0f;
    if (distance > truncation) sample_weight *= free_space_weight;  // free space only
    voxel_update.apply(sdf[i], weight[i], std::min(distance, truncation), sample_weight,
                       intensity ? intensity + i : nullptr,
                       intensity ? pixel_intensities[p] : 0.0f);
    drift = std::max(drift, std::abs(sdf[i] - old_sdf));
    topology = topology || (old_weight > 0.0f) != (weight[i] > 0.0f) ||
               (old_weight >= mesh_min_weight) != (weight[i] >= mesh_min_weight) ||
               (old_sdf < 0.0f) != (sdf[i] < 0.0f);
    ++updated;
  }
};

// Points as separate coordinate arrays: the transforms of a block's voxels
// vectorise, and projectMany takes them so.
struct PointArrays {
  std::vector<float> x, y, z;
  void resize(std::size_t n) {
    x.resize(n);
    y.resize(n);
    z.resize(n);
  }
};

// Raw pointers to the coordinates (the compiler cannot prove the vectors'
// members unchanged by stores through others and would reload them).
struct PointPointers {
  float* x;
  float* y;
  float* z;
  explicit PointPointers(PointArrays& arrays) : x(arrays.x.data()), y(arrays.y.data()), z(arrays.z.data()) {}
  Eigen::Vector3f operator[](std::size_t i) const { return {x[i], y[i], z[i]}; }
  void set(std::size_t i, const Eigen::Vector3f& point) const {
    x[i] = point.x();
    y[i] = point.y();
    z[i] = point.z();
  }
};

// to = offset + linear * (i, j, k) for each of count lattice coordinates,
// rounded as Eigen's `offset + linear * v` (its 3-term sums associate to the
// right), so that the voxel positions are those of the Eigen expression.
RANGE_IMAGE_MAPPING_SIMD_CLONES
void transformLattice(const Eigen::Vector3f& offset, const Eigen::Matrix3f& linear, const float* __restrict i_all,
                      const float* __restrict j_all, const float* __restrict k_all, std::size_t count,
                      float* __restrict x, float* __restrict y, float* __restrict z) {
  const float m00 = linear(0, 0), m01 = linear(0, 1), m02 = linear(0, 2);
  const float m10 = linear(1, 0), m11 = linear(1, 1), m12 = linear(1, 2);
  const float m20 = linear(2, 0), m21 = linear(2, 1), m22 = linear(2, 2);
  const float ox = offset.x(), oy = offset.y(), oz = offset.z();
  for (std::size_t n = 0; n < count; ++n) {  // vectorised
    const float i = i_all[n], j = j_all[n], k = k_all[n];
    x[n] = ox + (m00 * i + (m01 * j + m02 * k));
    y[n] = oy + (m10 * i + (m11 * j + m12 * k));
    z[n] = oz + (m20 * i + (m21 * j + m22 * k));
  }
}

// Voxel positions and their projections for one block, reused per thread.
struct BlockBuffers {
  // points: lidar frame at the scan time; moved: each voxel in the frame its
  // pixel was measured in (the column's, for a moving sensor); scratch:
  // points projected in passes over a few voxels (motion refinement, feet
  // on planes).
  PointArrays points, moved, scratch;
  std::vector<ProjectedPixel> pixels;
  std::vector<uint8_t> hits;
  // Motion refinement: the voxels still to refine, packed for projectMany,
  // and the column whose motion places each.
  std::vector<uint32_t> pending;
  std::vector<int> motion_columns;
  std::vector<ProjectedPixel> pending_pixels;
  std::vector<uint8_t> pending_hits;
  // The block's selected voxels (those of its activated cells), in order:
  // index in the block and lattice coordinates (i, j, k).
  std::vector<uint32_t> voxel_index;
  PointArrays lattice;
  void resize(std::size_t voxels) {
    if (voxel_index.size() == voxels) return;
    voxel_index.resize(voxels);
    lattice.resize(voxels);
    points.resize(voxels);
    moved.resize(voxels);
    scratch.resize(voxels);
    pixels.resize(voxels);
    hits.resize(voxels);
    motion_columns.resize(voxels);
    pending.resize(voxels);
    pending_pixels.resize(voxels);
    pending_hits.resize(voxels);
  }
};

// A block some activated cell falls in: its squared distance from the sensor
// (in blocks), its cells, the grid's block if it has it, its azimuth.
struct ActivatedBlock {
  double distance;
  BlockKey key;
  CellMask cells;
  VoxelBlock* block;
  float azimuth;
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
  if (signed_distance != SignedDistance::kAlongRay && signed_distance != SignedDistance::kPointToPlane)
    throw MappingError("signed_distance must be kAlongRay or kPointToPlane, got " +
                       std::to_string(int(signed_distance)));
  requireFiniteOption(mesh_tolerance_voxels, "mesh_tolerance_voxels");
  if (mesh_tolerance_voxels < 0.0)
    throw MappingError("mesh_tolerance_voxels must be >= 0 (0 = mark every change), got " +
                       numberText(mesh_tolerance_voxels));
  if (!(free_space_weight > 0.0f && free_space_weight <= 1.0f))
    throw MappingError("free_space_weight must be in (0, 1], got " + numberText(free_space_weight));
  requireFiniteOption(plane_fill_m, "plane_fill_m");
  if (plane_fill_m < 0.0)
    throw MappingError("plane_fill_m must be >= 0 (0 = the truncation), got " + numberText(plane_fill_m));
  if (!(mesh_min_weight >= 0.0f) || !std::isfinite(mesh_min_weight))
    throw MappingError("mesh_min_weight must be >= 0 and finite, got " + numberText(mesh_min_weight));
}

struct TsdfIntegrator::Workspace {
  tbb::enumerable_thread_specific<BlockCells> thread_blocks;
  tbb::enumerable_thread_specific<std::size_t> thread_points_used{0};
  tbb::enumerable_thread_specific<BlockBuffers> thread_buffers;
  BlockCells merged_blocks;
  ActivationCells cells;
  std::vector<CellMask> touched_cells;     // per touched block: its activated cells
  std::vector<uint8_t> created;            // per touched block
  std::vector<ActivatedBlock> activated;    // the blocks the scan's cells fall in, nearest first
  std::vector<VoxelBlock*> new_blocks;     // for touched_keys_: the blocks not in the grid before
  std::vector<uint8_t> new_created;
  std::vector<uint32_t> integration_order; // touched blocks by azimuth
  std::vector<float> azimuth;              // per touched block, in the lidar frame
  std::vector<uint32_t> voxels_updated;    // per touched block
  std::vector<uint32_t> voxels_selected;   // per touched block
  std::vector<float> block_drift;          // per touched block: largest |sdf change| of a voxel
  std::vector<uint8_t> block_topology;     // per touched block: a voxel's sign or observation changed
  std::vector<uint8_t> block_observed;     // per touched block: some voxel has weight > 0
  std::vector<ColumnMotion> column_motion_inverse;  // scan-time frame -> column-time frame
  std::vector<float> column_time;                   // seconds after the scan time
  std::vector<float> sample_weight;        // per pixel; empty: every sample weighs 1
  VertexNormalMap normals;   // point-to-plane distances and incidence weighting
  std::vector<PixelPlane> pixel_planes;    // point-to-plane
  std::vector<uint8_t> near_seam;          // per column: no plane (moving sweeps)
  std::vector<float> pixel_angle;          // per row: the larger of its row and column spacing, radians
};

struct TsdfIntegrator::DriftSinceMarked {
  tsl::robin_map<BlockKey, float, BlockKeyHash> drift;
};

namespace {

// The sensor's motion within a sweep, per column (scan_motion.h).
struct SweepMotion {
  // Per column (pointers, not vector references: one load less in the
  // voxel loops, where the compiler does not hoist the vectors' data).
  const ColumnMotion* inverse;  // scan-time frame -> column-time frame
  const float* time;            // column time after the scan time, s
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
// column: the range then errs by at most time * |v| <= voxel / 10 (1 cm at
// 10 cm voxels, the sensor's noise; voxel / 50 cost outdoor_car a quarter
// of the integration time and changed no F-score in the fourth digit), and a turn
// shifts the voxel by at most a quarter of a column (rotation about the
// origin leaves ranges alone). Never below two column periods, which the
// discrete column cannot resolve anyway.
float motionTimeTolerance(const Twist& twist, double voxel_size, int columns, float column_period_s) {
  constexpr double kRangeErrorInVoxels = 1.0 / 10.0;
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

// The rows from the lowest beam to the highest.
std::vector<int> rowsByAltitude(const LidarIntrinsics& intrinsics) {
  std::vector<int> by_altitude(intrinsics.rows);
  for (int v = 0; v < intrinsics.rows; ++v) by_altitude[v] = v;
  std::sort(by_altitude.begin(), by_altitude.end(),
            [&](int a, int b) { return intrinsics.altitude_rad[a] < intrinsics.altitude_rad[b]; });
  return by_altitude;
}

// The voxels picked by `voxels` (count of them, points of the scan-time
// frame) moved into the frames of their columns, columns[n] for voxels[n]:
// SweepMotion::toColumnFrame on plain floats, rounded as Eigen's
// `rotation * point + translation` (its 3-term sums associate to the right,
// the translation added last), so the coordinates are the same.
RANGE_IMAGE_MAPPING_SIMD_CLONES
void moveIntoColumnFrames(const ColumnMotion* inverse, const int* __restrict columns,
                          const uint32_t* __restrict voxels, const float* __restrict x_all,
                          const float* __restrict y_all, const float* __restrict z_all, std::size_t count,
                          float* __restrict x, float* __restrict y, float* __restrict z) {
  static_assert(sizeof(ColumnMotion) == 12 * sizeof(float), "column-major 3 x 4, unpadded");
  const float* __restrict motion = inverse[0].data();
  for (std::size_t n = 0; n < count; ++n) {  // vectorised
    const float* m = motion + 12 * std::size_t(columns[n]);
    const uint32_t i = voxels[n];
    const float px = x_all[i], py = y_all[i], pz = z_all[i];
    x[n] = (m[0] * px + (m[3] * py + m[6] * pz)) + m[9];
    y[n] = (m[1] * px + (m[4] * py + m[7] * pz)) + m[10];
    z[n] = (m[2] * px + (m[5] * py + m[8] * pz)) + m[11];
  }
}

// Pi of a block's voxels into the moving sensor: each voxel as the sensor
// saw it when the column that measured it fired (the fixed point above, for
// every voxel). All voxels are first projected as the block centre's column
// saw them (the block's lattice moved once, no motion per voxel): that gives
// each voxel's own column, stagger included, up to the little motion between
// the two columns. Voxels whose column was measured too far in time from the
// motion used are moved again with their own column's. Voxels that do not
// settle lie where the sweep's start and end overlap or leave a gap (the
// seam): they miss this scan rather than being averaged with the wrong
// sensor position.
// Works on the block's selected voxels (their lattice coordinates
// lattice_i, _j, _k and buffers.points,
// count of them); leaves each voxel hit in the frame of its column in
// buffers.moved.
void projectIntoMovingSensor(const LidarModel& model, const SweepMotion& motion, const Eigen::Vector3f& first,
                             const Eigen::Matrix3f& lattice_steps, int edge, const float* lattice_i,
                             const float* lattice_j, const float* lattice_k, std::size_t count,
                             BlockBuffers& buffers) {
  const Eigen::Vector3f block_centre = first + lattice_steps * Eigen::Vector3f::Constant(0.5f * float(edge - 1));
  const int centre_column = columnSeenFromMovingSensor(model, motion, block_centre);
  const PointPointers points(buffers.points), moved(buffers.moved), scratch(buffers.scratch);
  ProjectedPixel* pixels = buffers.pixels.data();
  uint8_t* hits = buffers.hits.data();
  uint32_t* pending_voxels = buffers.pending.data();
  int* motion_columns = buffers.motion_columns.data();
  // A copy the compiler keeps in registers for the settle checks (the byte
  // stores to hits below might alias the original).
  const SweepMotion local_motion = motion;
  std::size_t pending = 0;
  if (centre_column >= 0) {
    // The block's lattice in the centre column's frame.
    const Eigen::Vector3f moved_first = motion.toColumnFrame(centre_column, first);
    const Eigen::Matrix3f moved_steps = motion.inverse[centre_column].leftCols<3>() * lattice_steps;
    transformLattice(moved_first, moved_steps, lattice_i, lattice_j, lattice_k, count, moved.x, moved.y, moved.z);
    model.projectMany(moved.x, moved.y, moved.z, count, pixels, hits);
    for (std::size_t i = 0; i < count; ++i) {
      // A miss here is a voxel off the vertical field of view by more than
      // the sensor moved between the two columns: it is left out.
      if (!hits[i]) continue;
      if (!local_motion.settled(centre_column, pixels[i].column)) pending_voxels[pending++] = uint32_t(i);
    }
  } else {  // the centre is outside the field of view: start from the scan-time projection
    model.projectMany(points.x, points.y, points.z, count, pixels, hits);
    for (std::size_t i = 0; i < count; ++i)
      if (hits[i]) pending_voxels[pending++] = uint32_t(i);
  }
  ProjectedPixel* pending_pixels = buffers.pending_pixels.data();
  uint8_t* pending_hits = buffers.pending_hits.data();
  for (int pass = 0; pass < kMotionRefinements && pending > 0; ++pass) {
    for (std::size_t n = 0; n < pending; ++n) motion_columns[n] = pixels[pending_voxels[n]].column;
    moveIntoColumnFrames(motion.inverse, motion_columns, pending_voxels, points.x, points.y, points.z, pending,
                         scratch.x, scratch.y, scratch.z);
    model.projectMany(scratch.x, scratch.y, scratch.z, pending, pending_pixels, pending_hits);
    for (std::size_t n = 0; n < pending; ++n) {
      const uint32_t i = pending_voxels[n];
      hits[i] = pending_hits[n];
      if (!pending_hits[n]) continue;
      pixels[i] = pending_pixels[n];
      moved.x[i] = scratch.x[n];
      moved.y[i] = scratch.y[n];
      moved.z[i] = scratch.z[n];
    }
    // Then the voxels still unsettled, packed in place (a separate pass: fewer
    // pointers live at once).
    std::size_t unsettled = 0;
    for (std::size_t n = 0; n < pending; ++n) {
      if (!pending_hits[n]) continue;
      if (!local_motion.settled(motion_columns[n], pending_pixels[n].column))
        pending_voxels[unsettled++] = pending_voxels[n];
    }
    pending = unsettled;
  }
  for (std::size_t n = 0; n < pending; ++n) hits[pending_voxels[n]] = 0;
}

// Per row, the angle between neighbouring pixels: the larger of the column
// spacing and the gaps to the beams next in altitude.
void computePixelAngles(const LidarModel& model, std::vector<float>& angle) {
  const std::vector<double>& altitude = model.intrinsics().altitude_rad;
  const int rows = model.rows();
  const std::vector<int> by_altitude = rowsByAltitude(model.intrinsics());
  const double column_angle = 2.0 * M_PI / model.columns();
  angle.assign(rows, float(column_angle));
  for (int rank = 0; rank < rows; ++rank) {
    double gap = column_angle;
    if (rank > 0) gap = std::max(gap, altitude[by_altitude[rank]] - altitude[by_altitude[rank - 1]]);
    if (rank + 1 < rows) gap = std::max(gap, altitude[by_altitude[rank + 1]] - altitude[by_altitude[rank]]);
    angle[by_altitude[rank]] = float(gap);
  }
}

// Columns whose normals may mix returns from both ends of a moving sweep:
// within reach of a jump in column time (the seam, where the last column
// meets the first, or the edge of the column window). The normal map takes
// neighbours across the columns (wrapping) and, in the rows above and below,
// at the same azimuth: up to the largest azimuth step between neighbouring
// rows away.
void findColumnsNearTheSeam(const LidarModel& model, const std::vector<float>& column_time, float column_period_s,
                            std::vector<uint8_t>& near_seam) {
  const int columns = model.columns(), rows = model.rows();
  double widest_step = 0.0;
  for (int v = 0; v + 1 < rows; ++v) {
    const Eigen::Vector3f &a = model.direction(0, v), &b = model.direction(0, v + 1);
    const double step = std::remainder(std::atan2(b.y(), b.x()) - std::atan2(a.y(), a.x()), 2.0 * M_PI);
    widest_step = std::max(widest_step, std::abs(step) * columns / (2.0 * M_PI));
  }
  const int reach = int(std::ceil(widest_step)) + 1;
  near_seam.assign(columns, 0);
  for (int u = 0; u < columns; ++u) {
    const int next = (u + 1) % columns;
    if (std::abs(column_time[next] - column_time[u]) <= 2.0f * column_period_s) continue;
    for (int d = -reach; d <= reach; ++d) near_seam[((u + d) % columns + columns) % columns] = 1;
  }
}

// The pixels' planes for point-to-plane distances. A voxel behind a pixel's
// point along the ray takes the plane distance within the truncation plus
// the pixel's footprint along the ray (range * pixel angle * tan(incidence)):
// as far as the neighbouring returns the normal was fitted to, and no
// farther than the truncation past the range clip. No plane where the
// normal may mix both ends of a moving sweep (near_seam, empty if still).
void computePixelPlanes(const LidarModel& model, const RangeImage& scan, const VertexNormalMap& normals,
                        float truncation, float min_range, float max_range, const std::vector<uint8_t>& near_seam,
                        std::vector<float>& pixel_angle, std::vector<PixelPlane>& planes) {
  computePixelAngles(model, pixel_angle);
  planes.resize(scan.range.size());
  const int columns = scan.columns();
  tbb::parallel_for(0, scan.rows(), [&](int v) {
    for (int u = 0; u < columns; ++u) {
      const std::size_t i = scan.index(v, u);
      PixelPlane& plane = planes[i];
      const Eigen::Vector3f& point = normals.points[i];
      plane.normal = normals.normals[i];
      plane.range = scan.range[i];
      if (!std::isfinite(plane.normal.x()) || !std::isfinite(point.x()) || (!near_seam.empty() && near_seam[u])) {
        plane.offset = plane.reach = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      plane.offset = plane.normal.dot(point);
      // Normals face the sensor: cos(incidence) = -n . ray direction.
      const float cosine = std::clamp(-plane.normal.dot(model.direction(u, v)), kSmallestPlaneCosine, 1.0f);
      const float tangent = std::sqrt(1.0f - cosine * cosine) / cosine;
      const float range = scan.range[i];
      const float clip_reach = std::max(truncation, std::min(max_range - range, range - min_range) + truncation);
      plane.reach = std::min(truncation + range * pixel_angle[v] * tangent, clip_reach);
    }
  });
}

}  // namespace

TsdfIntegrator::TsdfIntegrator(TsdfIntegratorOptions options)
    : options_(options), drift_(std::make_unique<DriftSinceMarked>()), workspace_(std::make_unique<Workspace>()) {}
TsdfIntegrator::~TsdfIntegrator() = default;
TsdfIntegrator::TsdfIntegrator(TsdfIntegrator&&) noexcept = default;
TsdfIntegrator& TsdfIntegrator::operator=(TsdfIntegrator&&) noexcept = default;

IntegrationStatistics TsdfIntegrator::integrate(VoxelBlockGrid& grid, const RangeImage& scan,
                                                const ScanPose& pose, const VertexNormalMap* normals) {
  return update(grid, scan, pose, 1.0f, normals);
}

IntegrationStatistics TsdfIntegrator::deintegrate(VoxelBlockGrid& grid, const RangeImage& scan,
                                                  const ScanPose& pose) {
  return update(grid, scan, pose, -1.0f, nullptr);
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
  if (pose.scan_time_ns == 0 && !pose.twist.isZero() &&
      std::any_of(scan.column_timestamp_ns.begin(), scan.column_timestamp_ns.end(), [](uint64_t t) { return t != 0; }))
    throw MappingError("scan pose has a twist but no scan_time_ns: the column motion needs the time the pose "
                       "refers to (scanTime())");
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
                                             const ScanPose& pose, float sign,
                                             const VertexNormalMap* given_normals) {
  validate(grid, scan, pose);
  if (given_normals && (given_normals->stride != 1 || given_normals->rows != scan.rows() ||
                        given_normals->columns != scan.columns() ||
                        given_normals->points.size() != std::size_t(scan.rows()) * scan.columns() ||
                        given_normals->normals.size() != given_normals->points.size()))
    throw MappingError("the given normal map is not the scan's at full resolution (" +
                       std::to_string(given_normals->rows) + " x " + std::to_string(given_normals->columns) +
                       ", stride " + std::to_string(given_normals->stride) + ")");
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
  const bool moving = computeColumnMotion(scan, pose.scan_time_ns, pose.twist, column_motion_);
  float time_tolerance_s = 0.0f, column_period_s = 0.0f;
  if (moving) {
    work.column_motion_inverse.resize(columns);
    work.column_time.resize(columns);
    const uint64_t scan_time = pose.scan_time_ns;
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
    column_period_s = (latest - earliest) / float(std::max(timed_columns - 1, 1));
    time_tolerance_s = motionTimeTolerance(pose.twist, grid.voxelSize(), columns, column_period_s);
  }

  // Image-domain normals (the normal map's own points and normals, lidar
  // frame of each column), for point-to-plane distances and incidence weights.
  const bool point_to_plane = options_.signed_distance == SignedDistance::kPointToPlane;
  if ((point_to_plane || options_.incidence_weighting) && !given_normals)
    computeVertexNormalMap(scan, 1, NormalMapOptions{}, work.normals);
  const VertexNormalMap& normals = given_normals ? *given_normals : work.normals;
  if (point_to_plane) {
    work.near_seam.clear();
    if (moving) findColumnsNearTheSeam(model, work.column_time, column_period_s, work.near_seam);
    computePixelPlanes(model, scan, normals, truncation, min_range, max_range, work.near_seam, work.pixel_angle,
                       work.pixel_planes);
  }

  // Optional per-pixel sample weights.
  const bool weighted = options_.range_weighting || options_.incidence_weighting;
  if (weighted) {
    work.sample_weight.assign(scan.range.size(), 1.0f);
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
          const float cosine = -normals.normals[i].dot(model.direction(u, v));
          weight *= std::isfinite(cosine) ? std::max(cosine, kMinimumIncidenceWeight) : kMinimumIncidenceWeight;
        }
        work.sample_weight[i] = weight;
      }
    });
  }

  // 1. Activation: the cells (and their blocks) the beam crosses within the
  // truncation band around each return (paper section 4.2: activate blocks
  // near each point), or within the plane's reach for point-to-plane distances.
  const Clock::time_point activation_start = Clock::now();
  const double block_size = grid.blockSize();
  const Eigen::Isometry3d world_from_lidar = pose.world_from_lidar;
  const int stride = options_.point_stride;
  const int strided_rows = (rows + stride - 1) / stride;
  ActivationCells& cells = work.cells;
  cells.configure(grid.blockEdge());
  const double cell_size = cells.cellSize(grid.voxelSize());
  const float free_space_activation = float(kFreeSpaceActivationVoxels * grid.voxelSize());
  for (BlockCells& blocks : work.thread_blocks) blocks.clear();
  for (std::size_t& count : work.thread_points_used) count = 0;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, strided_rows, kActivationRowsPerTask), [&](const tbb::blocked_range<int>& range) {
        BlockCells& blocks = work.thread_blocks.local();
        std::size_t& used = work.thread_points_used.local();
        const int low_bits = cells.cells_per_edge - 1, shift = cells.shift, cells_per_edge = cells.cells_per_edge;
        BlockKey previous(std::numeric_limits<int>::min(), 0, 0), previous_block = previous;
        CellMask* previous_mask = nullptr;  // valid until the next insertion into `blocks`
        const auto insert = [&](const BlockKey& cell) {
          // Neighbouring pixels mostly cross the same cells and blocks: skip the hash then.
          if (cell == previous) return;
          previous = cell;
          const BlockKey block(cell.x() >> shift, cell.y() >> shift, cell.z() >> shift);  // floor division
          if (block != previous_block || previous_mask == nullptr) {
            previous_block = block;
            previous_mask = &blocks[block];
          }
          *previous_mask |= CellMask(1) << ((cell.x() & low_bits) +
                                            cells_per_edge * ((cell.y() & low_bits) + cells_per_edge * (cell.z() & low_bits)));
        };
        for (int strided_row = range.begin(); strided_row != range.end(); ++strided_row) {
          const int v = strided_row * stride;
          for (int u = 0; u < columns; u += stride) {
            const float r = scan.range[scan.index(v, u)];
            if (!(r >= min_range && r <= max_range)) continue;  // also NaN
            ++used;
            // Point-to-plane reaches along the pixel's plane towards its
            // neighbours' returns (kPlaneActivationShare of the way).
            float reach = truncation;
            if (point_to_plane) {
              const float plane_reach = work.pixel_planes[scan.index(v, u)].reach;
              if (std::isfinite(plane_reach)) reach = truncation + kPlaneActivationShare * (plane_reach - truncation);
            }
            Eigen::Vector3f near_point = model.unproject(u, v, std::max(r - reach - free_space_activation, 0.0f));
            Eigen::Vector3f far_point = model.unproject(u, v, r + reach);
            if (moving) {
              const ColumnMotion& motion = column_motion_[u];
              near_point = motion.leftCols<3>() * near_point + motion.col(3);
              far_point = motion.leftCols<3>() * far_point + motion.col(3);
            }
            visitBlocksOnSegment((world_from_lidar * near_point.cast<double>()) / cell_size,
                                 (world_from_lidar * far_point.cast<double>()) / cell_size, insert);
          }
        }
      });
  statistics.points_used = work.thread_points_used.combine(std::plus<std::size_t>());
  work.merged_blocks.clear();
  for (const BlockCells& blocks : work.thread_blocks)
    for (const auto& [key, mask] : blocks) work.merged_blocks[key] |= mask;
  // Nearest blocks first, so that a memory budget running out keeps the
  // sensor's surroundings; ties broken by key so that the order (and the
  // grid's pool slots) does not depend on the threads. A strict order on
  // distinct keys: any sort gives the same sequence.
  const Eigen::Vector3d sensor_in_blocks = world_from_lidar.translation() / block_size -
                                           Eigen::Vector3d::Constant(0.5);
  std::vector<ActivatedBlock>& activated = work.activated;
  activated.clear();
  for (const auto& [key, mask] : work.merged_blocks)
    activated.push_back({(key.cast<double>() - sensor_in_blocks).squaredNorm(), key, mask, nullptr, 0.0f});
  tbb::parallel_sort(activated.begin(), activated.end(), [](const ActivatedBlock& a, const ActivatedBlock& b) {
    if (a.distance != b.distance) return a.distance < b.distance;
    return latticeKeyLess(a.key, b.key);
  });
  // The blocks already in the grid are looked up in parallel (finds only);
  // the new ones are then created in that order, on one thread. Each block's
  // azimuth in the lidar frame too, for the integration order below.
  const Eigen::Isometry3d lidar_from_world = world_from_lidar.inverse();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, activated.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t n = range.begin(); n != range.end(); ++n) {
                        ActivatedBlock& entry = activated[n];
                        entry.block = grid.find(entry.key);
                        const Eigen::Vector3d centre =
                            lidar_from_world * (grid.voxelPosition(entry.key, 0, 0, 0) +
                                                Eigen::Vector3d::Constant(0.5 * block_size));
                        entry.azimuth = float(std::atan2(centre.y(), centre.x()));
                      }
                    });
  touched_keys_.clear();
  if (adding)
    for (const ActivatedBlock& entry : activated)
      if (entry.block == nullptr) touched_keys_.push_back(entry.key);
  work.new_blocks.resize(touched_keys_.size());
  work.new_created.resize(touched_keys_.size());
  grid.activateMany(touched_keys_.data(), touched_keys_.size(), work.new_blocks.data(), work.new_created.data());
  touched_blocks_.clear();
  work.created.clear();
  work.touched_cells.clear();
  work.azimuth.clear();
  std::size_t next_new = 0;
  for (const ActivatedBlock& entry : activated) {
    bool created = false;
    VoxelBlock* block = entry.block;
    if (block == nullptr && adding) {
      created = work.new_created[next_new];
      block = work.new_blocks[next_new++];
    }
    if (block == nullptr) {
      // Removing: a block that is not there holds nothing to remove.
      if (adding) ++statistics.blocks_refused;
      continue;
    }
    touched_blocks_.push_back(block);
    work.created.push_back(created);
    work.touched_cells.push_back(entry.cells);
    work.azimuth.push_back(entry.azimuth);
  }
  statistics.activation_seconds = secondsSince(activation_start);

  // 2. Integration: every voxel of the activated cells projected with Pi
  // (eq. 8), d = Omega(u, v) - r (eq. 9), averaged (eq. 10). One block per
  // task, so no two threads write one voxel.
  const Clock::time_point integration_start = Clock::now();
  const Eigen::Matrix3f lattice_steps = (lidar_from_world.linear() * grid.voxelSize()).cast<float>();
  const int edge = grid.blockEdge();
  const std::size_t voxels = static_cast<std::size_t>(grid.voxelsPerBlock());
  const bool with_intensity = grid.options().store_intensity && scan.intensity.size() == scan.range.size();
  const VoxelUpdate voxel_update{options_.max_weight, adding};
  const SweepMotion sweep_motion{work.column_motion_inverse.data(), work.column_time.data(), time_tolerance_s};
  work.voxels_updated.assign(touched_blocks_.size(), 0);
  work.voxels_selected.assign(touched_blocks_.size(), 0);
  work.block_drift.assign(touched_blocks_.size(), 0.0f);
  work.block_topology.assign(touched_blocks_.size(), 0);
  work.block_observed.assign(touched_blocks_.size(), 1);
  const float mesh_min_weight = options_.mesh_min_weight;
  const float free_space_weight = options_.free_space_weight;
  const PixelPlane* planes = point_to_plane ? work.pixel_planes.data() : nullptr;
  const Eigen::Vector3f* pixel_points = point_to_plane ? normals.points.data() : nullptr;
  const float plane_tolerance = float(kPlaneSeenToleranceVoxels * grid.voxelSize());
  const float plane_fill = float(options_.planeFillFor(grid.options()));
  const float plane_fill_squared = plane_fill * plane_fill;
  const float* ranges = scan.range.data();
  const float* intensities = with_intensity ? scan.intensity.data() : nullptr;
  const float* sample_weights = weighted ? work.sample_weight.data() : nullptr;
  // Blocks in azimuth order: neighbouring blocks of one task read
  // neighbouring pixels, which stay in cache (ties by index: one order).
  work.integration_order.resize(touched_blocks_.size());
  for (std::size_t b = 0; b < touched_blocks_.size(); ++b) work.integration_order[b] = uint32_t(b);
  tbb::parallel_sort(work.integration_order.begin(), work.integration_order.end(), [&](uint32_t a, uint32_t b) {
    return work.azimuth[a] < work.azimuth[b] || (work.azimuth[a] == work.azimuth[b] && a < b);
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, touched_blocks_.size(), 1),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    BlockBuffers& buffers = work.thread_buffers.local();
    // Copies the compiler keeps in registers (it would reload the captured
    // originals after every voxel store, which might alias them).
    const std::size_t image_columns = std::size_t(columns);
    const float range_low = min_range, range_high = max_range, band = truncation;
    buffers.resize(voxels);
    for (std::size_t ordered = range.begin(); ordered != range.end(); ++ordered) {
      const std::size_t b = work.integration_order[ordered];
      VoxelBlock& block = *touched_blocks_[b];
      // Voxel positions in the lidar frame, relative to the block's first
      // voxel in double so that floats keep millimetres far from the origin.
      const Eigen::Vector3f first =
          (lidar_from_world * grid.voxelPosition(block.key, 0, 0, 0)).cast<float>();
      // Only the voxels of the cells activated.
      const CellMask activated = work.touched_cells[b];
      const CellMask* selecting_cells = cells.selecting_cells.data();
      const float *cell_i = cells.lattice_i.data(), *cell_j = cells.lattice_j.data(), *cell_k = cells.lattice_k.data();
      const PointPointers lattice(buffers.lattice), points(buffers.points);
      uint32_t* selected = buffers.voxel_index.data();
      // The selection: the table's entries where it has them (read in place),
      // else the buffers filled below.
      const uint32_t* voxel_index = selected;
      const float *lattice_i = lattice.x, *lattice_j = lattice.y, *lattice_k = lattice.z;
      const std::size_t voxel_rows = std::size_t(edge) * edge;
      std::size_t count = 0;
      if (!cells.selection_start.empty()) {
        const std::size_t first_selected = cells.selection_start[activated];
        count = cells.selection_start[activated + 1] - first_selected;
        voxel_index = cells.selection_index.data() + first_selected;
        lattice_i = cells.selection_i.data() + first_selected;
        lattice_j = cells.selection_j.data() + first_selected;
        lattice_k = cells.selection_k.data() + first_selected;
      } else {
        for (std::size_t row = 0; row < voxel_rows; ++row) {
          if (!(cells.row_selecting_cells[row] & activated)) continue;
          for (std::size_t v = row * edge, row_end = v + edge; v < row_end; ++v) {
            if (!(selecting_cells[v] & activated)) continue;
            selected[count] = uint32_t(v);
            lattice.x[count] = cell_i[v];
            lattice.y[count] = cell_j[v];
            lattice.z[count] = cell_k[v];
            ++count;
          }
        }
      }
      transformLattice(first, lattice_steps, lattice_i, lattice_j, lattice_k, count, points.x, points.y, points.z);
      if (moving) {
        projectIntoMovingSensor(model, sweep_motion, first, lattice_steps, edge, lattice_i, lattice_j, lattice_k, count,
                                buffers);
      } else {
        model.projectMany(points.x, points.y, points.z, count, buffers.pixels.data(), buffers.hits.data());
      }
      // Raw pointers: the compiler cannot prove the vectors' members unchanged
      // by the stores below and would reload them for every voxel.
      const uint8_t* hits = buffers.hits.data();
      const ProjectedPixel* pixels = buffers.pixels.data();
      const PointPointers frame_points = moving ? PointPointers(buffers.moved) : points;
      float* sdf = block.sdf.data();
      float* weight = block.weight.data();
      float* intensity = with_intensity ? block.intensity.data() : nullptr;
      BlockWriter write{sdf,          weight,          intensity,        sample_weights, intensities,
                        voxel_update, truncation,      mesh_min_weight, free_space_weight};
      if (!planes) {
        for (std::size_t i = 0; i < count; ++i) {
          if (!hits[i]) continue;
          const std::size_t p = std::size_t(pixels[i].row) * image_columns + pixels[i].column;
          const float measured = ranges[p];
          if (!(measured >= range_low && measured <= range_high)) continue;  // also NaN
          const float along_ray = measured - pixels[i].range;                // eq. 9
          if (along_ray < -band) continue;  // occluded: behind the surface
          write(voxel_index[i], p, along_ray);
        }
      } else {
        // Voxels beyond the pixel's truncation band wait for the check that
        // the plane was seen under them: their foot points on the plane are
        // projected together (the projection buffers are free now).
        std::size_t unverified = 0;
        uint32_t* unverified_voxels = buffers.pending.data();
        const PointPointers feet(buffers.scratch);
        for (std::size_t i = 0; i < count; ++i) {
          if (!hits[i]) continue;
          const std::size_t p = std::size_t(pixels[i].row) * image_columns + pixels[i].column;
          const PixelPlane& plane = planes[p];
          if (!(plane.range >= range_low && plane.range <= range_high)) continue;  // also NaN
          const float along_ray = plane.range - pixels[i].range;                  // eq. 9
          if (!(std::abs(along_ray) <= plane.reach)) {  // also without a normal (NaN)
            if (along_ray < -band) continue;  // occluded: behind the surface
            write(voxel_index[i], p, along_ray);
            continue;
          }
          const float to_plane = plane.distance(frame_points[i]);
          if (to_plane < -band) continue;  // behind the surface
          // Within the pixel's own truncation band the plane is the pixel's surface.
          if (std::abs(along_ray) <= band) {
            write(voxel_index[i], p, to_plane);
          } else {
            unverified_voxels[unverified] = uint32_t(i);
            feet.set(unverified++, frame_points[i] - to_plane * plane.normal);
          }
        }
        if (unverified > 0) {
          ProjectedPixel* foot_pixels = buffers.pending_pixels.data();
          uint8_t* foot_hits = buffers.pending_hits.data();
          model.projectMany(feet.x, feet.y, feet.z, unverified, foot_pixels, foot_hits);
          for (std::size_t n = 0; n < unverified; ++n) {
            const std::size_t i = unverified_voxels[n];
            const std::size_t p = std::size_t(pixels[i].row) * image_columns + pixels[i].column;
            const PixelPlane& plane = planes[p];
            const float to_plane = plane.distance(frame_points[i]);
            // Farther along the ray the plane counts only where the image saw
            // it under the voxel (not past an object's edge, into its shadow),
            // and within plane_fill of that return (not across wide gaps
            // between beam rings).
            const std::size_t q = std::size_t(foot_pixels[n].row) * image_columns + foot_pixels[n].column;
            if (foot_hits[n] && std::abs(plane.distance(pixel_points[q])) <= plane_tolerance &&
                (feet[n] - pixel_points[q]).squaredNorm() <= plane_fill_squared) {
              write(voxel_index[i], p, to_plane);  // (NaN for a pixel without a return fails the test)
              continue;
            }
            // Otherwise eq. 9, but only where both distances put the voxel in
            // front: eq. 9 may say "in front" only because the voxel is off
            // the pixel's central ray.
            const float along_ray = plane.range - pixels[i].range;
            if (along_ray > 0.0f && to_plane >= 0.0f) write(voxel_index[i], p, along_ray);
          }
        }
      }
      work.voxels_updated[b] = write.updated;
      work.voxels_selected[b] = uint32_t(count);
      work.block_drift[b] = write.drift;
      work.block_topology[b] = write.topology;
      // Only a new block, or one a scan was removed from, may hold no
      // observation now (it goes below); checked here, in parallel.
      if (work.created[b] || !adding)
        work.block_observed[b] = std::any_of(weight, weight + voxels, [](float w) { return w > 0.0f; });
    }
  });

  // Bookkeeping: blocks changed in a way that matters to the mesh carry this
  // generation; blocks that hold no observation any more (created for
  // nothing, or emptied by removal) go.
  statistics.blocks_touched = touched_blocks_.size();
  const float mesh_tolerance = float(options_.mesh_tolerance_voxels * grid.voxelSize());
  auto& drift_since_marked = drift_->drift;
  for (std::size_t b = 0; b < touched_blocks_.size(); ++b) {
    VoxelBlock& block = *touched_blocks_[b];
    statistics.voxels_updated += work.voxels_updated[b];
    statistics.voxels_selected += work.voxels_selected[b];
    if ((work.created[b] || !adding) && !work.block_observed[b]) {
      grid.remove(block.key);
      if (mesh_tolerance > 0.0f) drift_since_marked.erase(block.key);
      if (!adding) ++statistics.blocks_removed;
      continue;
    }
    if (work.created[b]) ++statistics.blocks_created;
    if (work.voxels_updated[b] == 0) continue;
    bool mark = true;
    if (mesh_tolerance > 0.0f && !work.created[b] && !work.block_topology[b]) {
      // A new block starts from nothing: whatever its slot held before is forgotten.
      float& drift = drift_since_marked[block.key];
      drift += work.block_drift[b];
      mark = drift > mesh_tolerance;
    }
    if (!mark) continue;
    block.changed_generation = generation;
    ++statistics.blocks_marked;
    if (mesh_tolerance > 0.0f) drift_since_marked.erase(block.key);
  }
  // Entries of blocks removed from the grid by others (memory radius, clear):
  // pruned once they could outnumber the grid's blocks.
  if (drift_since_marked.size() > 2 * grid.blockCount() + 1024) {
    for (auto entry = drift_since_marked.begin(); entry != drift_since_marked.end();)
      entry = grid.find(entry->first) ? std::next(entry) : drift_since_marked.erase(entry);
  }
  statistics.integration_seconds = secondsSince(integration_start);
  return statistics;
}

}  // namespace range_image_mapping::mapping
