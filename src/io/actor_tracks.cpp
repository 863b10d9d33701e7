#include "range_image_mapping/io/actor_tracks.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace range_image_mapping::io {
namespace {

bool hasSpace(const std::string& text) {
  return text.empty() || text.find_first_of(" \t\r\n") != std::string::npos;
}

// Exactly count finite numbers after the keyword.
std::vector<double> readNumbers(std::istringstream& stream, std::size_t count, const std::string& where) {
  std::vector<double> numbers;
  for (double value; stream >> value;) numbers.push_back(value);
  if (!stream.eof() || numbers.size() != count)
    throw ActorTracksError(where + ": expected " + std::to_string(count) + " numbers");
  for (const double value : numbers)
    if (!std::isfinite(value)) throw ActorTracksError(where + ": a number is not finite");
  return numbers;
}

}  // namespace

void writeActorTracks(const std::string& path, const std::vector<ActorTrack>& tracks, const std::string& comment) {
  for (const ActorTrack& track : tracks) {
    if (hasSpace(track.kind) || hasSpace(track.name))
      throw std::invalid_argument("writeActorTracks: kind and name must be one word, got '" + track.kind + "', '" +
                                  track.name + "'");
    if (track.times_s.size() != track.world_from_actor.size())
      throw std::invalid_argument("writeActorTracks: " + track.name + " has " + std::to_string(track.times_s.size()) +
                                  " times and " + std::to_string(track.world_from_actor.size()) + " poses");
  }
  std::ofstream file(path);
  if (!file) throw ActorTracksError("actor tracks: cannot write " + path);
  file << "# rim actor tracks: per actor its boxes in its own frame (x forward, y left, z up, origin on the\n"
          "# ground; centre and half sizes, metres), then T_world_actor per scan (t x y z qx qy qz qw).\n"
          "# label: the per-pixel label of the actor's returns (0 is the static world).\n";
  if (!comment.empty()) file << "# " << comment << "\n";
  file << std::setprecision(9);
  for (const ActorTrack& track : tracks) {
    file << "actor " << track.label << " " << track.kind << " " << track.name << "\n";
    for (const ActorTrackBox& box : track.boxes)
      file << "box " << box.centre_m.x() << " " << box.centre_m.y() << " " << box.centre_m.z() << " "
           << box.half_size_m.x() << " " << box.half_size_m.y() << " " << box.half_size_m.z() << "\n";
    for (std::size_t i = 0; i < track.times_s.size(); ++i) {
      const Eigen::Vector3d t = track.world_from_actor[i].translation();
      const Eigen::Quaterniond q(track.world_from_actor[i].linear());
      file << "pose " << std::fixed << std::setprecision(9) << track.times_s[i] << " " << t.x() << " " << t.y()
           << " " << t.z() << " " << q.x() << " " << q.y() << " " << q.z() << " " << q.w() << "\n"
           << std::defaultfloat;
    }
  }
  if (!file.flush()) throw ActorTracksError("actor tracks: writing " + path + " failed");
}

std::vector<ActorTrack> readActorTracks(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw ActorTracksError("actor tracks: cannot open " + path);
  std::vector<ActorTrack> tracks;
  std::set<int> labels;
  std::string line;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    const std::string where = "actor tracks: " + path + " line " + std::to_string(line_number);
    std::istringstream stream(line);
    std::string keyword;
    if (!(stream >> keyword) || keyword[0] == '#') continue;
    if (keyword == "actor") {
      ActorTrack track;
      std::string rest;
      if (!(stream >> track.label >> track.kind >> track.name) || (stream >> rest))
        throw ActorTracksError(where + ": expected 'actor <label> <kind> <name>'");
      if (track.label < 1 || !labels.insert(track.label).second)
        throw ActorTracksError(where + ": label " + std::to_string(track.label) + " is below 1 or used twice");
      tracks.push_back(std::move(track));
      continue;
    }
    if (keyword != "box" && keyword != "pose") throw ActorTracksError(where + ": unknown line '" + keyword + "'");
    if (tracks.empty()) throw ActorTracksError(where + ": " + keyword + " before any actor line");
    ActorTrack& track = tracks.back();
    if (keyword == "box") {
      const std::vector<double> n = readNumbers(stream, 6, where);
      ActorTrackBox box;
      box.centre_m = Eigen::Vector3d(n[0], n[1], n[2]);
      box.half_size_m = Eigen::Vector3d(n[3], n[4], n[5]);
      if (!(box.half_size_m.minCoeff() > 0.0)) throw ActorTracksError(where + ": a half size is not positive");
      track.boxes.push_back(box);
    } else {
      const std::vector<double> n = readNumbers(stream, 8, where);
      const Eigen::Quaterniond q(n[7], n[4], n[5], n[6]);
      if (std::abs(q.norm() - 1.0) > 1e-3) throw ActorTracksError(where + ": the quaternion is not of unit norm");
      if (!track.times_s.empty() && !(n[0] > track.times_s.back()))
        throw ActorTracksError(where + ": times must increase");
      Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
      pose.linear() = q.normalized().toRotationMatrix();
      pose.translation() = Eigen::Vector3d(n[1], n[2], n[3]);
      track.times_s.push_back(n[0]);
      track.world_from_actor.push_back(pose);
    }
  }
  return tracks;
}

}  // namespace range_image_mapping::io
