// Multi-scale projective point-to-plane registration (paper section 4.1):
// source points are projected with Pi into the target range image, and the
// target point and normal found there form the pair. No k-d tree.
#pragma once

#include "range_image_mapping/normal_map.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <array>
#include <limits>
#include <vector>

namespace range_image_mapping::registration {

struct RobustKernel {
  enum class Type { kPseudoHuber, kBarron } type = Type::kPseudoHuber;
  double scale_m = 0.5;  // paper: 0.5 m outdoors, 0.2 m indoors
  double alpha = 1.0;    // Barron's shape (1: pseudo-Huber/Charbonnier, 0: Cauchy, -2: Geman-McClure)
};

// Weight of a residual in iteratively reweighted least squares, rho'(e)/e up
// to a constant: pseudo-Huber 1/sqrt(1+(e/c)^2); Barron's general kernel
// ((e/c)^2/|alpha-2| + 1)^(alpha/2-1) (alpha 2: least squares, 0: Cauchy).
double robustWeight(const RobustKernel& kernel, double residual_m);

struct RegistrationOptions {
  std::vector<int> strides{4, 2, 1};        // pyramid levels, coarse to fine
  std::vector<int> iterations{20, 20, 10};  // Gauss-Newton iterations per level (paper)
  int source_stride = 1;                    // extra subsampling of the source at every level
  // Pairs further apart are rejected (full resolution); 0: twice the kernel
  // scale, 1 m outdoors and 0.4 m indoors with the paper's kernels. A gate
  // that does not shrink with the kernel admits, indoors, pairs across
  // doorways that bias the pose (pairwise_registration_benchmark).
  double max_correspondence_distance_m = 0.0;
  // A level of stride s accepts pairs s times as far apart: the coarse
  // levels capture motions beyond the gate (from an identity guess, scans
  // metres apart), the fine ones reject outliers.
  bool gate_grows_with_stride = true;
  // A level before the last with fewer pairs than this is passed over (the
  // pose it started from kept for the next level): a sparse sensor's coarse
  // levels (a VLP-16 at stride 4: four rows, 7-21 pairs) cannot hold six
  // degrees of freedom, and their steps ran away by metres. 0: off.
  int min_coarse_pairs = 100;
  double min_normal_cosine = 0.8;           // source and target normals must agree
  // Source pixels without a normal of their own are paired too (the pair's
  // plane is the target's; the normals' agreement is checked where the
  // source has one): on a sparse sensor the ground's pixels fail the
  // source's depth-jump test, and the target's normals come from a model
  // that has a plane there (LocalModelOptions::normal_radius_m).
  bool pair_source_without_normals = false;
  // Pairs are weighted by the area their pixel covers, range^2 up to this
  // range (and equally beyond it): the static world, far and wide, then
  // outweighs a near object that fills many pixels. 0: every pair alike.
  // On a sensor with sparse rows the registration lowers it further, from
  // the target model's beam spacing (ProjectiveIcp::areaWeightRange).
  double area_weight_max_range_m = 25.0;
  RobustKernel kernel;
  NormalMapOptions normals;
  // On a sensor with sparse rows (sparseRows), full-resolution normals must
  // lie on one plane with their neighbours, within this (normalsFor). A
  // normal across two surfaces, which the range-jump test lets through far
  // away where rows are metres apart, puts the pair's plane off the true
  // surface, and the far pairs' leverage turns that into roll and pitch
  // pulled towards the previous scan's. 0: off.
  double sparse_rows_chord_offset_m = 0.02;
  double convergence_rotation_rad = 1e-5;   // early exit when an update is smaller
  double convergence_translation_m = 1e-5;
  // Levels before the last stop when an update is below the thresholds times
  // this times their stride (they only seed the finer levels).
  double coarse_convergence_scale = 100.0;

  double correspondenceDistance() const {
    return max_correspondence_distance_m > 0.0 ? max_correspondence_distance_m : 2.0 * kernel.scale_m;
  }
};

// A sensor whose rows are a degree or more apart (median spacing): VLP-16,
// HDL-32E, RS-LiDAR-16; not an OS-1-128, HDL-64E or VLP-32C.
bool sparseRows(const LidarModel& model);

// The normals the registration computes for a sensor's images: options.normals,
// with sparse_rows_chord_offset_m on a sensor with sparse rows.
NormalMapOptions normalsFor(const RegistrationOptions& options, const LidarModel& model);

// The area weight's cap with a sensor: options.area_weight_max_range_m,
// lowered on a sensor with sparse rows (its median beam spacing).
double areaWeightRange(const RegistrationOptions& options, const LidarModel& model);

struct RegistrationResult {
  Eigen::Isometry3d target_from_source = Eigen::Isometry3d::Identity();
  // J^T W J of the last iteration, unknowns [rotation, translation] (a left
  // perturbation T <- Exp(delta) T in the target frame).
  Eigen::Matrix<double, 6, 6> hessian = Eigen::Matrix<double, 6, 6>::Zero();
  std::size_t inliers = 0;       // pairs in the last iteration
  int iterations = 0;            // over all levels
  // Coarse levels left with the pose they started from: fewer pairs than
  // RegistrationOptions::min_coarse_pairs (a sensor too sparse for the stride).
  int levels_passed_over = 0;
  double condition_number = 0;   // of the hessian; infinity when it is singular (no pairs)
  double residual_rms_m = 0;
};

// The part of the pyramid one align() call runs: levels first_level up to
// (not including) end_level, clamped to the pyramid, each with at most
// max_iterations Gauss-Newton steps (0: RegistrationOptions::iterations).
struct LevelSchedule {
  std::size_t first_level = 0;
  std::size_t end_level = std::numeric_limits<std::size_t>::max();
  int max_iterations = 0;
};

// The target's vertex/normal maps are built once per target and reused.
// align() reuses internal buffers: one instance must not align from several
// threads at once (each call is parallel inside, with TBB).
class ProjectiveIcp {
 public:
  // Throws std::invalid_argument for inconsistent options (strides and
  // iterations of different lengths, stride < 1, non-positive gates or scale).
  explicit ProjectiveIcp(RegistrationOptions options = {});

  // Prepares the target pyramid (normals at every level) from strided views
  // of the image; the image itself is not kept. Throws std::invalid_argument
  // for an image without a model or destaggered.
  void setTarget(const RangeImage& target);
  // The same, with the image's full-resolution map already computed (with
  // these options' normals; its points may have been moved, e.g. deskewed):
  // levels of stride 1 copy it instead of computing it again. Throws
  // std::invalid_argument when its size or stride does not match the image.
  void setTarget(const RangeImage& target, const VertexNormalMap& full_resolution);
  bool hasTarget() const { return target_model_ != nullptr; }
  // A target rendered elsewhere (the odometry's local model): one map per
  // stride of the options, each point filed under the level pixel it
  // projects to with `model` (levelPixelIndex), or association will not find
  // it. The maps are swapped in: `levels` gets the previous target's buffers
  // back. Throws std::invalid_argument when their number or strides differ.
  void setTarget(const LidarModelConstPtr& model, std::vector<VertexNormalMap>& levels);
  const VertexNormalMap& targetLevel(std::size_t level) const { return target_levels_.at(level); }
  // Source points in their own lidar frame (e.g. deskewed), with normals;
  // pixels without a normal are not used (unless
  // pair_source_without_normals). At level s the source is read every
  // s * source_stride pixels. Throws std::runtime_error without a target,
  // std::invalid_argument for a non-finite initial pose. Levels before
  // first_level are skipped (a refinement from an already close pose).
  // Replaces the source given to setSource().
  RegistrationResult align(const VertexNormalMap& source_full_resolution,
                           const Eigen::Isometry3d& initial_target_from_source,
                           std::size_t first_level = 0) const;
  // Only the levels and iterations of `schedule` (e.g. one step at the finest
  // level between two deskews). No level in the range: the initial pose, no
  // pairs.
  RegistrationResult align(const VertexNormalMap& source_full_resolution,
                           const Eigen::Isometry3d& initial_target_from_source, const LevelSchedule& schedule) const;
  // Convenience: computes the source map itself.
  RegistrationResult align(const RangeImage& source, const Eigen::Isometry3d& initial_target_from_source) const;

  // For several registrations of one source (e.g. with different deskews):
  // its pixels with normals, subsampled for every level, kept until the next
  // setSource() or align(map). Throws std::invalid_argument when the map's
  // sizes do not match.
  void setSource(const VertexNormalMap& source_full_resolution);
  // Registers the source given to setSource(). With column_motion (per
  // full-resolution column, [R | t] from the column's time to the scan time,
  // as computeColumnMotion gives it), every point is moved by its column's
  // motion first: the source is deskewed inside the registration, at no
  // extra cost per point, instead of in a moved copy. Throws
  // std::runtime_error without a target or a source, std::invalid_argument
  // for a non-finite initial pose or column_motion too short for the source.
  RegistrationResult alignSource(const Eigen::Isometry3d& initial_target_from_source,
                                 const LevelSchedule& schedule = {},
                                 const std::vector<ColumnMotion>& column_motion = {}) const;

  const RegistrationOptions& options() const { return options_; }
  // The area weight's cap in use with the current target's sensor: the
  // option, lowered on a sensor with sparse rows (0 before any target).
  double areaWeightRange() const { return area_weight_range_m_; }
  // Whether source pixels without a normal pair with the current target's
  // sensor: the option, except where its normals are checked in line
  // (normalsFor), which then give the ground its own.
  bool pairsSourceWithoutNormals() const { return pairs_without_normals_; }

 private:
  // One level's source pixels with normals, and the full-resolution column
  // of each (for its column motion). The points' and normals' coordinates
  // as separate arrays (x, y, z of the points, then of the normals): the
  // per-point passes vectorise over them.
  struct SourceLevel {
    enum Coordinate { kX, kY, kZ, kNormalX, kNormalY, kNormalZ, kCoordinates };
    std::array<std::vector<float>, kCoordinates> coordinates;
    std::vector<int> columns;
    std::size_t size() const { return columns.size(); }
  };
  void prepareSource(const VertexNormalMap& source) const;
  void setTargetModel(const LidarModelConstPtr& model);

  RegistrationOptions options_;
  LidarModelConstPtr target_model_;
  double area_weight_range_m_ = 0.0;  // from the target model's beam spacing, once per target sensor
  bool pairs_without_normals_ = false;  // pairsSourceWithoutNormals(), once per target sensor
  std::vector<VertexNormalMap> target_levels_;  // one per options_.strides entry
  std::vector<LevelPixelTables> target_index_tables_;  // one per options_.strides entry
  // Reused between calls (no per-frame allocation in steady state).
  mutable VertexNormalMap source_map_;
  mutable std::vector<SourceLevel> source_levels_;  // one per options_.strides entry
  mutable std::vector<std::size_t> row_offsets_;    // prepareSource: first kept pixel of each row
  mutable bool has_source_ = false;
  mutable std::size_t source_full_columns_ = 0;  // columns of the source's full resolution
  // Per column, target_from_source * motion: entry j (column-major [R | t])
  // of column u at j * columns + u, 12 arrays the moving pass gathers from.
  mutable std::vector<float> column_transforms_;
};

}  // namespace range_image_mapping::registration
