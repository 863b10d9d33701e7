#include "range_image_mapping/sensor_model_estimation.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numeric>
#include <sstream>

namespace range_image_mapping {
namespace {

constexpr double kTwoPi = 2.0 * M_PI;
constexpr double kRadPerDeg = M_PI / 180.0;

// A measured point as the estimation sees it (double: the fits below resolve
// 1e-6 rad, where float's rounding of the differences would show).
struct Sample {
  double z = 0.0;
  double rho = 0.0;      // horizontal distance from the z axis
  double azimuth = 0.0;  // atan2(y, x)
  int scan = 0;
  int ring = -1;  // the cloud's ring field, -1 without one
  int beam = -1;  // cluster of elevations; -1: a stray, in no beam
  // cos of the angle at the axis between the point and its beam origin
  // (theta_lut - delta); 1 until the azimuth offsets are known.
  double cos_origin_angle = 1.0;
};

// Elevation of the point seen from its beam origin, which sits r0 from the
// axis and z0 above the cloud's origin.
inline double elevationFromOrigin(const Sample& s, double r0, double z0) {
  const double horizontal =
      std::sqrt(std::max(1e-12, s.rho * s.rho + r0 * r0 - 2.0 * r0 * s.rho * s.cos_origin_angle));
  return std::atan2(s.z - z0, horizontal);
}

inline double wrapPi(double angle) { return std::remainder(angle, kTwoPi); }

std::vector<Sample> collectSamples(const std::vector<PointCloudInput>& scans, double min_rho, bool use_rings) {
  std::vector<Sample> samples;
  std::size_t total = 0;
  for (const PointCloudInput& scan : scans) total += scan.size();
  samples.reserve(total);
  for (std::size_t s = 0; s < scans.size(); ++s) {
    const PointCloudInput& scan = scans[s];
    scan.validate();
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const Eigen::Vector3f& p = scan.points[i];
      if (!p.allFinite() || p.isZero()) continue;  // drivers' "no return"
      Sample sample;
      sample.rho = std::hypot(double(p.x()), double(p.y()));
      if (sample.rho < min_rho) continue;
      sample.z = p.z();
      sample.azimuth = std::atan2(double(p.y()), double(p.x()));
      sample.scan = static_cast<int>(s);
      if (use_rings) sample.ring = scan.ring[i];
      samples.push_back(sample);
    }
  }
  return samples;
}

// ---------------------------------------------------------------- beam origin, coarse
// How concentrated the elevations are: the sum of squared counts of a fine
// histogram, largest when every beam's points fall into as few bins as they
// can (an autofocus measure; it needs no beam assignment yet).
double elevationSharpness(const std::vector<const Sample*>& subset, double r0, double z0, double bin_rad) {
  const std::size_t bins = static_cast<std::size_t>(std::ceil(M_PI / bin_rad)) + 1;
  std::vector<uint32_t> histogram(bins, 0);
  for (const Sample* s : subset) {
    const double e = elevationFromOrigin(*s, r0, z0) + M_PI / 2;
    ++histogram[std::min(bins - 1, static_cast<std::size_t>(e / bin_rad))];
  }
  double sum = 0.0;
  for (const uint32_t count : histogram) sum += double(count) * count;
  return sum;
}

struct Origin {
  double radius_m = 0.0;
  double height_m = 0.0;
};

// Grid search of (r0, z0) by sharpness, then a finer grid around the best.
Origin searchBeamOrigin(const std::vector<Sample>& samples, const SensorEstimationOptions& options) {
  constexpr std::size_t kSubset = 30000;
  std::vector<const Sample*> subset;
  const std::size_t stride = std::max<std::size_t>(1, samples.size() / kSubset);
  for (std::size_t i = 0; i < samples.size(); i += stride) subset.push_back(&samples[i]);

  Origin best;
  double radius_step = options.max_beam_origin_radius_m / 15.0;
  double height_step = options.max_beam_origin_height_m / 20.0;
  double radius_low = 0.0, radius_high = options.max_beam_origin_radius_m;
  double height_low = -options.max_beam_origin_height_m, height_high = options.max_beam_origin_height_m;
  for (const double bin_deg : {0.02, 0.005}) {
    std::vector<Origin> grid;
    for (double r = radius_low; r <= radius_high + 1e-12; r += radius_step)
      for (double z = height_low; z <= height_high + 1e-12; z += height_step) grid.push_back({r, z});
    std::vector<double> score(grid.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, grid.size()), [&](const auto& range) {
      for (std::size_t g = range.begin(); g != range.end(); ++g)
        score[g] = elevationSharpness(subset, grid[g].radius_m, grid[g].height_m, bin_deg * kRadPerDeg);
    });
    // The smallest origin among equal scores (far-only data cannot see it).
    std::size_t chosen = 0;
    for (std::size_t g = 1; g < grid.size(); ++g)
      if (score[g] > score[chosen] * (1.0 + 1e-9)) chosen = g;
    best = grid[chosen];
    radius_low = std::max(0.0, best.radius_m - radius_step);
    radius_high = std::min(options.max_beam_origin_radius_m, best.radius_m + radius_step);
    height_low = best.height_m - height_step;
    height_high = best.height_m + height_step;
    radius_step /= 8.0;
    height_step /= 8.0;
  }
  return best;
}

// ---------------------------------------------------------------- beams
struct Cluster {
  double low_rad = 0.0, high_rad = 0.0;  // elevation interval
  std::size_t count = 0;
};

// Elevation clusters: a fine histogram, lightly smoothed, cut at its valleys;
// neighbouring hills whose valley stays above half the lower peak are one
// beam (noise on a wide cluster), and hills with few points are strays.
std::vector<Cluster> clusterElevations(const std::vector<double>& elevations, double min_share) {
  const double bin = 0.005 * kRadPerDeg;
  const auto [low_it, high_it] = std::minmax_element(elevations.begin(), elevations.end());
  const double low = *low_it - 20 * bin;
  const std::size_t bins = static_cast<std::size_t>((*high_it + 20 * bin - low) / bin) + 1;
  std::vector<double> histogram(bins, 0.0);
  for (const double e : elevations) histogram[static_cast<std::size_t>((e - low) / bin)] += 1.0;
  // Gaussian of 3 bins (0.015 deg): finer than any beam spacing (0.1 deg and up).
  constexpr int kRadius = 9;
  std::vector<double> kernel(2 * kRadius + 1);
  for (int k = -kRadius; k <= kRadius; ++k) kernel[k + kRadius] = std::exp(-0.5 * (k * k) / 9.0);
  std::vector<double> smooth(bins, 0.0);
  for (std::size_t b = 0; b < bins; ++b) {
    if (histogram[b] == 0.0) continue;
    for (int k = -kRadius; k <= kRadius; ++k) {
      const long target = long(b) + k;
      if (target >= 0 && target < long(bins)) smooth[target] += histogram[b] * kernel[k + kRadius];
    }
  }
  // Hills: each local maximum, with the minimum between it and the next.
  struct Hill {
    double peak;
    std::size_t valley_after;  // bin of the valley towards the next hill
  };
  std::vector<Hill> hills;
  for (std::size_t b = 1; b + 1 < bins; ++b) {
    if (!(smooth[b] > 0.0 && smooth[b] >= smooth[b - 1] && smooth[b] > smooth[b + 1])) continue;
    if (!hills.empty()) {
      // The valley between the previous hill's peak and this one.
      std::size_t valley = hills.back().valley_after;
      for (std::size_t c = valley; c < b; ++c)
        if (smooth[c] < smooth[valley]) valley = c;
      hills.back().valley_after = valley;
    }
    hills.push_back({smooth[b], b});
  }
  if (hills.empty()) return {};
  // Merge across the shallowest valleys first.
  constexpr double kValleyRatio = 0.5;
  for (;;) {
    std::size_t merge = hills.size();
    double highest_ratio = kValleyRatio;
    for (std::size_t h = 0; h + 1 < hills.size(); ++h) {
      const double ratio = smooth[hills[h].valley_after] / std::min(hills[h].peak, hills[h + 1].peak);
      if (ratio > highest_ratio) highest_ratio = ratio, merge = h;
    }
    if (merge == hills.size()) break;
    hills[merge].peak = std::max(hills[merge].peak, hills[merge + 1].peak);
    hills[merge].valley_after = hills[merge + 1].valley_after;
    hills.erase(hills.begin() + merge + 1);
  }
  std::vector<Cluster> clusters(hills.size());
  for (std::size_t h = 0; h < hills.size(); ++h) {
    clusters[h].low_rad = h == 0 ? -M_PI : low + (hills[h - 1].valley_after + 0.5) * bin;
    clusters[h].high_rad = h + 1 == hills.size() ? M_PI : low + (hills[h].valley_after + 0.5) * bin;
  }
  for (const double e : elevations) {
    const auto it = std::upper_bound(clusters.begin(), clusters.end(), e,
                                     [](double value, const Cluster& c) { return value < c.high_rad; });
    if (it != clusters.end()) ++it->count;
  }
  std::vector<std::size_t> counts;
  for (const Cluster& c : clusters) counts.push_back(c.count);
  std::nth_element(counts.begin(), counts.begin() + counts.size() / 2, counts.end());
  const double minimum = min_share * double(counts[counts.size() / 2]);
  clusters.erase(std::remove_if(clusters.begin(), clusters.end(),
                                [&](const Cluster& c) { return double(c.count) < minimum; }),
                 clusters.end());
  return clusters;
}

void assignBeams(std::vector<Sample>& samples, const std::vector<Cluster>& clusters, const Origin& origin) {
  for (Sample& s : samples) {
    const double e = elevationFromOrigin(s, origin.radius_m, origin.height_m);
    const auto it = std::upper_bound(clusters.begin(), clusters.end(), e,
                                     [](double value, const Cluster& c) { return value < c.high_rad; });
    s.beam = it != clusters.end() && e >= it->low_rad ? static_cast<int>(it - clusters.begin()) : -1;
  }
}

// ---------------------------------------------------------------- beam origin, fine
// Per beam: the robust centre and spread of its points' elevations, and
// whether each point is an inlier (within 4 sigma of the median, sigma from
// the MAD), so mixed pixels and strays do not pull the fits.
struct BeamElevations {
  std::vector<double> median, sigma;
};

// Every sample's elevation from the origin (NaN for strays), computed once
// for the beams' statistics and whatever else a pass needs of them.
std::vector<double> elevationsFromOrigin(const std::vector<Sample>& samples, const Origin& origin) {
  std::vector<double> elevations(samples.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 4096), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i)
      elevations[i] = samples[i].beam >= 0 ? elevationFromOrigin(samples[i], origin.radius_m, origin.height_m)
                                           : std::numeric_limits<double>::quiet_NaN();
  });
  return elevations;
}

BeamElevations beamElevationStatistics(const std::vector<Sample>& samples, const std::vector<double>& elevations,
                                       int beams) {
  std::vector<std::vector<double>> by_beam(beams);
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (samples[i].beam >= 0) by_beam[samples[i].beam].push_back(elevations[i]);
  BeamElevations result;
  result.median.assign(beams, 0.0);
  result.sigma.assign(beams, 0.0);
  for (int b = 0; b < beams; ++b) {
    std::vector<double>& e = by_beam[b];
    if (e.empty()) continue;
    std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
    const double median = e[e.size() / 2];
    for (double& value : e) value = std::abs(value - median);
    std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
    result.median[b] = median;
    // A floor of 1e-5 rad: exact data has a MAD of float rounding.
    result.sigma[b] = std::max(1e-5, 1.4826 * e[e.size() / 2]);
  }
  return result;
}

// Gauss-Newton on the beam origin with every beam's altitude as the mean of
// its inliers (the altitudes eliminated: the 2x2 system of the centred
// Jacobians). Exact data converges to float rounding.
Origin refineBeamOrigin(const std::vector<Sample>& samples, int beams, Origin origin,
                        const SensorEstimationOptions& options) {
  if (!options.estimate_beam_origin) return origin;
  for (int iteration = 0; iteration < 10; ++iteration) {
    const std::vector<double> elevations = elevationsFromOrigin(samples, origin);
    const BeamElevations statistics = beamElevationStatistics(samples, elevations, beams);
    struct Sums {
      double n = 0, e = 0, jr = 0, jz = 0;
    };
    std::vector<Sums> means(beams);
    struct Row {
      int beam;
      double e, jr, jz;
    };
    std::vector<Row> rows;
    rows.reserve(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const Sample& s = samples[i];
      if (s.beam < 0) continue;
      const double r0 = origin.radius_m;
      const double horizontal =
          std::sqrt(std::max(1e-12, s.rho * s.rho + r0 * r0 - 2.0 * r0 * s.rho * s.cos_origin_angle));
      const double dz = s.z - origin.height_m;
      const double e = elevations[i];
      if (std::abs(e - statistics.median[s.beam]) > 4.0 * statistics.sigma[s.beam]) continue;
      const double norm2 = horizontal * horizontal + dz * dz;
      const double jr = -dz / norm2 * (r0 - s.rho * s.cos_origin_angle) / horizontal;
      const double jz = -horizontal / norm2;
      rows.push_back({s.beam, e, jr, jz});
      Sums& m = means[s.beam];
      m.n += 1, m.e += e, m.jr += jr, m.jz += jz;
    }
    Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
    Eigen::Vector2d gradient = Eigen::Vector2d::Zero();
    for (const Row& row : rows) {
      const Sums& m = means[row.beam];
      const Eigen::Vector2d j(row.jr - m.jr / m.n, row.jz - m.jz / m.n);
      normal += j * j.transpose();
      gradient += j * (row.e - m.e / m.n);
    }
    // Levenberg damping: far-only data barely sees the origin.
    normal.diagonal() *= 1.0 + 1e-6;
    normal.diagonal().array() += 1e-12;
    const Eigen::Vector2d step = -normal.ldlt().solve(gradient);
    if (!step.allFinite()) break;
    origin.radius_m = std::clamp(origin.radius_m + step.x(), 0.0, options.max_beam_origin_radius_m);
    origin.height_m = std::clamp(origin.height_m + step.y(), -options.max_beam_origin_height_m,
                                 options.max_beam_origin_height_m);
    if (step.norm() < 1e-8) break;
  }
  return origin;
}

// ---------------------------------------------------------------- columns
// Samples of one beam in one scan: a Velodyne's firing grid drifts from
// revolution to revolution, so phases are only compared within a scan.
std::vector<std::vector<std::size_t>> groupByScanAndBeam(const std::vector<Sample>& samples, int scans,
                                                         int beams) {
  std::vector<std::vector<std::size_t>> groups(static_cast<std::size_t>(scans) * beams);
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (samples[i].beam >= 0) groups[std::size_t(samples[i].scan) * beams + samples[i].beam].push_back(i);
  groups.erase(std::remove_if(groups.begin(), groups.end(), [](const auto& g) { return g.size() < 2; }),
               groups.end());
  return groups;
}

// The most common azimuth step between neighbouring points of one beam
// (missing returns make larger gaps, never smaller ones).
double modalAzimuthStep(const std::vector<Sample>& samples, const std::vector<std::vector<std::size_t>>& groups) {
  const double bin = 0.0005 * kRadPerDeg, largest = 3.0 * kRadPerDeg;
  std::vector<double> histogram(static_cast<std::size_t>(largest / bin) + 1, 0.0);
  std::vector<double> azimuths;
  for (const auto& group : groups) {
    azimuths.clear();
    for (const std::size_t i : group) azimuths.push_back(samples[i].azimuth);
    std::sort(azimuths.begin(), azimuths.end());
    for (std::size_t k = 1; k < azimuths.size(); ++k) {
      const double gap = azimuths[k] - azimuths[k - 1];
      if (gap > 0.01 * kRadPerDeg && gap < largest) histogram[static_cast<std::size_t>(gap / bin)] += 1.0;
    }
  }
  // Smoothed over +-2 bins: encoder jitter spreads the steps a little.
  std::size_t best = 0;
  double best_value = -1.0;
  for (std::size_t b = 2; b + 2 < histogram.size(); ++b) {
    const double value = histogram[b - 2] + histogram[b - 1] + histogram[b] + histogram[b + 1] + histogram[b + 2];
    if (value > best_value) best_value = value, best = b;
  }
  if (best_value <= 0.0) throw SensorEstimationError("sensor estimation: no azimuth step found between the points of a beam");
  return (best + 0.5) * bin;
}

// Phase coherence of the samples on a grid of W columns: 1 when every
// scan's beam sits exactly on the grid, whatever its offset.
// For every W from low to high: how coherent the points' phases are on a grid
// of multiple * W columns, the mean over the groups of |sum of e^(i W a)| per
// point. e^(i W a) is stepped from W to W + 1 by one complex product (two
// sines per point instead of two per point and W; rounding about 1e-14).
std::vector<double> gridCoherence(const std::vector<Sample>& samples,
                                  const std::vector<std::vector<std::size_t>>& groups, int low, int high,
                                  int multiple) {
  const int count = high - low + 1;
  // Per group, then summed in the groups' order: the same on any thread count.
  std::vector<double> by_group(groups.size() * std::size_t(count));
  tbb::parallel_for(std::size_t(0), groups.size(), [&](std::size_t g) {
    std::vector<std::complex<double>> sum(count, 0.0);
    for (const std::size_t i : groups[g]) {
      const double azimuth = multiple * samples[i].azimuth;
      std::complex<double> phase = std::polar(1.0, low * azimuth);
      const std::complex<double> step = std::polar(1.0, azimuth);
      for (int w = 0; w < count; ++w, phase *= step) sum[w] += phase;
    }
    for (int w = 0; w < count; ++w) by_group[g * count + w] = std::abs(sum[w]);
  });
  std::vector<double> coherence(count, 0.0);
  double total = 0.0;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    for (int w = 0; w < count; ++w) coherence[w] += by_group[g * count + w];
    total += groups[g].size();
  }
  for (double& value : coherence) value = total > 0 ? value / total : 0.0;
  return coherence;
}

// Share of the points that share a pixel with a neighbour of their beam on a
// grid of W columns, each scan's beam centred on it.
double collisionShare(const std::vector<Sample>& samples, const std::vector<std::vector<std::size_t>>& groups,
                      int columns) {
  std::size_t collisions = 0, total = 0;
  std::vector<long> cells;
  const double step = kTwoPi / columns;
  for (const auto& group : groups) {
    std::complex<double> sum = 0.0;
    for (const std::size_t i : group) sum += std::polar(1.0, columns * samples[i].azimuth);
    const double phase = std::arg(sum) / columns;
    cells.clear();
    for (const std::size_t i : group) {
      long cell = std::lround((samples[i].azimuth - phase) / step);
      cell = ((cell % columns) + columns) % columns;
      cells.push_back(cell);
    }
    std::sort(cells.begin(), cells.end());
    collisions += cells.size() - static_cast<std::size_t>(std::unique(cells.begin(), cells.end()) - cells.begin());
    total += group.size();
  }
  return total ? double(collisions) / double(total) : 0.0;
}

int estimateColumns(const std::vector<Sample>& samples, const std::vector<std::vector<std::size_t>>& groups,
                    const SensorEstimationOptions& options, double* step_rad) {
  *step_rad = modalAzimuthStep(samples, groups);
  if (options.columns > 0) return options.columns;
  const int guess = static_cast<int>(std::lround(kTwoPi / *step_rad));
  // The integer W nearest the true step: the grid on which the points are
  // most coherent, within 3 % of the modal step (a free-running Velodyne's W
  // is not an integer; its nearest integer drifts under a column per turn).
  // Coherence on the grid of half the step too: the HDL-64E fires on both,
  // in runs, so that on the full step its points cancel out (KITTI: 0.01 on
  // the full step, 0.28 on the half step).
  std::vector<std::vector<std::size_t>> subset;  // 200000 points are plenty
  std::size_t used = 0;
  for (const auto& group : groups) {
    if (used > 200000) break;
    subset.push_back(group);
    used += group.size();
  }
  const int low = std::max(8, static_cast<int>(guess * 0.97)), high = static_cast<int>(guess * 1.03) + 1;
  const std::vector<double> full = gridCoherence(samples, subset, low, high, 1);
  const std::vector<double> half = gridCoherence(samples, subset, low, high, 2);
  const auto best_full = std::max_element(full.begin(), full.end());
  const auto best_half = std::max_element(half.begin(), half.end());
  if (*best_full < 0.5 * *best_half) return 2 * (low + static_cast<int>(best_half - half.begin()));
  const int base = low + static_cast<int>(best_full - full.begin());
  // Where beams still fire between the steps now and then, twice the columns
  // keep their points, if that halves the points lost to a shared pixel.
  const double base_share = collisionShare(samples, groups, base);
  if (base_share <= options.max_collision_share) return base;
  const double double_share = collisionShare(samples, groups, 2 * base);
  return double_share < 0.5 * base_share ? 2 * base : base;
}

// ---------------------------------------------------------------- azimuth offsets
// theta_lut of one beam. Its points sit on the encoder grid after
// theta_e = alpha - theta_lut + asin(r0 sin(theta_lut) / rho) (the closed form
// of the projection): the grid gives theta_lut modulo a column, and with a
// beam origin off the axis (r0 > 0) the asin term, which bends near points by
// an amount that depends on theta_lut itself, tells which multiple of the
// column it is. Without r0 the offset nearest zero is taken: any other
// multiple only renames the beam's columns.
// With search_multiple false the multiple of `offset` is kept and only the
// centring is redone (after the beam origin moved).
double estimateAzimuthOffset(const std::vector<Sample>& samples, const std::vector<std::size_t>& beam_samples,
                             int scans, int columns, double r0, bool search_multiple, double offset) {
  const double step = kTwoPi / columns;
  const auto encoderPhases = [&](const std::vector<std::size_t>& points, double offset) {
    // Per scan, the resultant of exp(i W theta_e), then summed over scans.
    std::vector<std::complex<double>> per_scan(scans, 0.0);
    const double sin_offset = std::sin(offset);
    for (const std::size_t i : points) {
      const Sample& s = samples[i];
      const double theta_e = s.azimuth - offset + std::asin(std::clamp(r0 * sin_offset / s.rho, -1.0, 1.0));
      per_scan[s.scan] += std::polar(1.0, columns * theta_e);
    }
    return per_scan;
  };
  const auto spread = [](const std::vector<std::complex<double>>& per_scan, std::size_t count) {
    double coherent = 0.0;
    for (const auto& sum : per_scan) coherent += std::abs(sum);
    return double(count) - coherent;  // sum over scans of n (1 - R): 0 on the grid
  };
  if (search_multiple) {
    // Phase without the r0 term: the offset modulo a column, centred near zero.
    std::complex<double> sum = 0.0;
    for (const std::size_t i : beam_samples) sum += std::polar(1.0, columns * samples[i].azimuth);
    offset = std::arg(sum) / columns;
  }
  if (search_multiple && r0 > 1e-4) {
    // The nearest points show the asin term most; 1500 of them decide.
    std::vector<std::size_t> nearest(beam_samples);
    const std::size_t keep = std::min<std::size_t>(1500, nearest.size());
    std::partial_sort(nearest.begin(), nearest.begin() + keep, nearest.end(),
                      [&](std::size_t a, std::size_t b) { return samples[a].rho < samples[b].rho; });
    nearest.resize(keep);
    nearest.erase(std::remove_if(nearest.begin(), nearest.end(),
                                 [&](std::size_t i) { return samples[i].rho < 4.0 * r0; }),
                  nearest.end());
    const int largest_multiple = static_cast<int>(20.0 * kRadPerDeg / step);
    double best_spread = std::numeric_limits<double>::infinity(), zero_spread = best_spread;
    double best_offset = offset;
    const int zero_multiple = 0;  // offset is already the multiple nearest zero
    for (int k = -largest_multiple; k <= largest_multiple; ++k) {
      const double candidate = offset + k * step;
      const double value = spread(encoderPhases(nearest, candidate), nearest.size());
      if (value < best_spread) best_spread = value, best_offset = candidate;
      if (k == zero_multiple) zero_spread = value;
    }
    // Only a clearly better multiple: noise must not pick one.
    if (best_spread < 0.5 * zero_spread) offset = best_offset;
  }
  // Centre the grid on the points, with the asin term of this offset.
  for (int iteration = 0; iteration < 3; ++iteration) {
    const std::vector<std::complex<double>> per_scan = encoderPhases(beam_samples, offset);
    const std::complex<double> total = std::accumulate(per_scan.begin(), per_scan.end(), std::complex<double>(0.0));
    offset += std::arg(total) / columns;
  }
  return std::remainder(offset, kTwoPi);
}

void setOriginAngles(std::vector<Sample>& samples, const std::vector<double>& offsets, double r0) {
  for (Sample& s : samples) {
    if (s.beam < 0) continue;
    const double offset = offsets[s.beam];
    const double delta = std::asin(std::clamp(r0 * std::sin(offset) / s.rho, -1.0, 1.0));
    s.cos_origin_angle = std::cos(offset - delta);
  }
}

}  // namespace

SensorEstimate estimateSensorModel(const std::vector<PointCloudInput>& scans, const SensorEstimationOptions& options) {
  const bool use_rings = options.use_ring_field && !scans.empty() &&
                         std::all_of(scans.begin(), scans.end(), [](const PointCloudInput& s) { return !s.ring.empty(); });
  std::vector<Sample> samples = collectSamples(scans, options.min_horizontal_range_m, use_rings);
  if (samples.size() < 1000)
    throw SensorEstimationError("sensor estimation: " + std::to_string(samples.size()) + " usable points in " +
                                std::to_string(scans.size()) + " clouds (at least 1000 measured points beyond " +
                                std::to_string(options.min_horizontal_range_m) + " m of the axis are needed)");

  // 1. Beams: rings, or clusters of elevation from the best beam origin.
  Origin origin;
  int beams = 0;
  std::vector<int> ring_of_beam;
  if (use_rings) {
    int largest = -1;
    for (const Sample& s : samples) largest = std::max(largest, s.ring);
    std::vector<int> beam_of_ring(largest + 1, -1);
    for (const Sample& s : samples) beam_of_ring[s.ring] = 0;
    for (int ring = 0; ring <= largest; ++ring)
      if (beam_of_ring[ring] == 0) beam_of_ring[ring] = beams++, ring_of_beam.push_back(ring);
    for (Sample& s : samples) s.beam = beam_of_ring[s.ring];
    if (options.estimate_beam_origin) origin = searchBeamOrigin(samples, options);
  } else {
    if (options.estimate_beam_origin) origin = searchBeamOrigin(samples, options);
    // Cluster, fit the origin to the clusters, and cluster again with it.
    for (int pass = 0; pass < 2; ++pass) {
      std::vector<double> elevations(samples.size());
      for (std::size_t i = 0; i < samples.size(); ++i)
        elevations[i] = elevationFromOrigin(samples[i], origin.radius_m, origin.height_m);
      const std::vector<Cluster> clusters = clusterElevations(elevations, options.min_beam_share);
      if (clusters.size() < 2)
        throw SensorEstimationError("sensor estimation: the points' elevations form " +
                                    std::to_string(clusters.size()) +
                                    " beam(s); a spinning multi-beam LiDAR was expected");
      beams = static_cast<int>(clusters.size());
      assignBeams(samples, clusters, origin);
      origin = refineBeamOrigin(samples, beams, origin, options);
    }
  }

  // 2. Columns from the azimuth step, then each beam's offset on that grid.
  const int scan_count = static_cast<int>(scans.size());
  const std::vector<std::vector<std::size_t>> groups = groupByScanAndBeam(samples, scan_count, beams);
  double step_rad = 0.0;
  const int columns = estimateColumns(samples, groups, options, &step_rad);
  std::vector<std::vector<std::size_t>> by_beam(beams);
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (samples[i].beam >= 0) by_beam[samples[i].beam].push_back(i);
  std::vector<double> offsets(beams, 0.0);
  const auto estimateOffsets = [&](bool search_multiple) {
    tbb::parallel_for(0, beams, [&](int b) {
      if (!by_beam[b].empty())
        offsets[b] = estimateAzimuthOffset(samples, by_beam[b], scan_count, columns, origin.radius_m,
                                           search_multiple, offsets[b]);
    });
  };
  estimateOffsets(true);

  // 3. With the offsets the beam origin of every point is known exactly:
  // refit the origin, then the offsets with it. The first origin took every
  // beam origin straight between the axis and the point, which makes r0
  // short by up to 2 % (cos 11 deg) and can pick a wrong multiple of a
  // column for the offset: the multiples are searched again with the
  // refined origin.
  for (int pass = 0; pass < 3; ++pass) {
    setOriginAngles(samples, offsets, origin.radius_m);
    origin = refineBeamOrigin(samples, beams, origin, options);
    estimateOffsets(pass == 0);
  }
  setOriginAngles(samples, offsets, origin.radius_m);

  // 4. Altitudes: the mean of each beam's inliers.
  const std::vector<double> elevations = elevationsFromOrigin(samples, origin);
  const BeamElevations statistics = beamElevationStatistics(samples, elevations, beams);
  std::vector<double> altitude_sum(beams, 0.0);
  std::vector<std::size_t> inliers(beams, 0), members(beams, 0);
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Sample& s = samples[i];
    if (s.beam < 0) continue;
    ++members[s.beam];
    const double e = elevations[i];
    if (std::abs(e - statistics.median[s.beam]) > 4.0 * statistics.sigma[s.beam]) continue;
    altitude_sum[s.beam] += e;
    ++inliers[s.beam];
  }

  // Rows from the highest beam down, as in Ouster's metadata.
  std::vector<int> beam_of_row(beams);
  std::iota(beam_of_row.begin(), beam_of_row.end(), 0);
  std::vector<double> altitude(beams);
  for (int b = 0; b < beams; ++b) altitude[b] = inliers[b] ? altitude_sum[b] / inliers[b] : statistics.median[b];
  std::stable_sort(beam_of_row.begin(), beam_of_row.end(), [&](int a, int b) { return altitude[a] > altitude[b]; });

  SensorEstimate estimate;
  LidarIntrinsics& intrinsics = estimate.intrinsics;
  intrinsics.rows = beams;
  intrinsics.columns = columns;
  intrinsics.beam_origin_radius_m = origin.radius_m;
  intrinsics.beam_origin_z_m = origin.height_m;
  intrinsics.sensor_model = use_rings ? "estimated from rings" : "estimated";
  const double column_step = kTwoPi / columns;
  for (int row = 0; row < beams; ++row) {
    const int b = beam_of_row[row];
    intrinsics.altitude_rad.push_back(altitude[b]);
    intrinsics.azimuth_offset_rad.push_back(offsets[b]);
    // Display only: destaggering lines the beams' columns up in azimuth.
    const int shift = static_cast<int>(std::lround(-offsets[b] / column_step));
    intrinsics.pixel_shift_by_row.push_back(((shift % columns) + columns) % columns);
    estimate.points_per_row.push_back(members[b]);
  }
  if (use_rings) {
    estimate.ring_to_row.assign(ring_of_beam.empty() ? 0 : *std::max_element(ring_of_beam.begin(), ring_of_beam.end()) + 1, -1);
    for (int row = 0; row < beams; ++row) estimate.ring_to_row[ring_of_beam[beam_of_row[row]]] = row;
  }
  intrinsics.validate();
  estimate.azimuth_step_deg = step_rad / kRadPerDeg;
  estimate.fit = measureSensorModelFit(scans, std::make_shared<const LidarModel>(intrinsics), estimate.ring_to_row);
  return estimate;
}

SensorModelFit measureSensorModelFit(const std::vector<PointCloudInput>& scans, const LidarModelConstPtr& model,
                                     const std::vector<int>& ring_to_row) {
  SensorModelFit fit;
  const LidarIntrinsics& intrinsics = model->intrinsics();
  const float origin_norm = static_cast<float>(std::hypot(intrinsics.beam_origin_radius_m, intrinsics.beam_origin_z_m));
  double elevation_sum = 0.0, azimuth_sum = 0.0;
  std::size_t residuals = 0;
  for (const PointCloudInput& scan : scans) {
    const bool by_ring = !ring_to_row.empty() && !scan.ring.empty();
    ProjectionStatistics statistics;
    if (by_ring)
      projectPointCloud(scan, model, ring_to_row, &statistics);
    else
      projectPointCloud(scan, model, &statistics);
    ++fit.scans;
    fit.measured_points += statistics.measured();
    fit.kept += statistics.kept;
    fit.outside_model += statistics.outside_model;
    fit.occluded += statistics.occluded;
    for (std::size_t i = 0; i < scan.size(); ++i) {
      const Eigen::Vector3f& p = scan.points[i];
      if (!p.allFinite() || p.isZero()) continue;
      std::optional<ProjectedPixel> pixel;
      if (by_ring) {
        const int ring = scan.ring[i];
        if (ring < static_cast<int>(ring_to_row.size()) && ring_to_row[ring] >= 0)
          pixel = model->projectOnRow(p, ring_to_row[ring]);
      } else {
        pixel = model->project(p);
      }
      if (!pixel) continue;
      // The pixel's ray from its beam origin against the point from there.
      const Eigen::Vector3f& d = model->direction(pixel->column, pixel->row);
      const Eigen::Vector3f origin = model->offset(pixel->column, pixel->row) + origin_norm * d;
      const Eigen::Vector3d q = (p - origin).cast<double>();
      const Eigen::Vector3d ray = d.cast<double>();
      const double elevation = std::atan2(q.z(), q.head<2>().norm()) - std::atan2(ray.z(), ray.head<2>().norm());
      const double azimuth = wrapPi(std::atan2(q.y(), q.x()) - std::atan2(ray.y(), ray.x()));
      elevation_sum += elevation * elevation;
      azimuth_sum += azimuth * azimuth;
      ++residuals;
    }
  }
  if (residuals) {
    fit.elevation_residual_deg = std::sqrt(elevation_sum / residuals) / kRadPerDeg;
    fit.azimuth_residual_deg = std::sqrt(azimuth_sum / residuals) / kRadPerDeg;
  }
  return fit;
}

}  // namespace range_image_mapping
