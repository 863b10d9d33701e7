// Moving actors' ground truth, as rim simulate writes it next to the poses
// (actors.txt): each actor's boxes in its own frame and its pose at every
// scan's time, so an evaluation can tell what a map kept of them. Text:
//   # comment lines
//   actor <label> <kind> <name>       label >= 1: the per-pixel label of its returns (0: static world)
//   box <cx> <cy> <cz> <hx> <hy> <hz> centre and half sizes in the actor frame, metres
//   pose <t> <x> <y> <z> <qx> <qy> <qz> <qw>   T_world_actor at time t (s), TUM order
// box and pose lines belong to the actor line above them.
#pragma once

#include <Eigen/Geometry>

#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// Missing or malformed; what() names the file, the line and the problem.
class ActorTracksError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ActorTrackBox {
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_size_m = Eigen::Vector3d::Zero();
};

struct ActorTrack {
  int label = 0;
  std::string kind;  // car, truck, pedestrian
  std::string name;  // one word
  std::vector<ActorTrackBox> boxes;
  std::vector<double> times_s;                       // increasing
  std::vector<Eigen::Isometry3d> world_from_actor;   // one per time
};

// Throws ActorTracksError when the file cannot be written, std::invalid_argument
// for a name or kind with white space, or times and poses of different counts.
void writeActorTracks(const std::string& path, const std::vector<ActorTrack>& tracks,
                      const std::string& comment = "");
// Throws ActorTracksError for anything malformed: an unknown line, a box or
// pose before any actor, a count of numbers, a value that is not finite, a half
// size that is not positive, a quaternion not of unit norm (1e-3), times that
// do not increase, a label below 1 or used twice.
std::vector<ActorTrack> readActorTracks(const std::string& path);

}  // namespace range_image_mapping::io
