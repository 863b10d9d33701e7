// What a map keeps of moving actors: the share of a reconstruction that lies
// inside the volumes the actors swept (io::readActorTracks, as rim simulate
// writes them). A map that rejects moving objects leaves nothing there.
#pragma once

#include "range_image_mapping/io/actor_tracks.h"

#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <vector>

namespace range_image_mapping::evaluation {

struct ActorTrailOptions {
  // Each box at each tracked pose, grown by this much sideways and upward
  // (a map blurs by a voxel or two) and raised by it at the bottom, so the
  // road under a truck or the sidewalk under a pedestrian does not count.
  double margin_m = 0.1;
};

struct ActorTrail {
  std::size_t points = 0;         // of the reconstruction (e.g. area samples of a mesh)
  std::size_t points_inside = 0;  // inside some swept volume
  double share = 0.0;             // points_inside / points
  struct PerKind {
    std::string kind;
    std::size_t points_inside = 0;
  };
  std::vector<PerKind> by_kind;  // car, truck, pedestrian: in order of first appearance
};

// Throws std::invalid_argument for a margin that is negative or not finite.
ActorTrail measureActorTrail(const std::vector<Eigen::Vector3f>& points, const std::vector<io::ActorTrack>& tracks,
                             const ActorTrailOptions& options = {});

}  // namespace range_image_mapping::evaluation
