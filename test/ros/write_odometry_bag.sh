#!/bin/sh
# Writes a simulated sequence with rim simulate from this package's devel or
# install space, for the <param command=...> of odometry_*.test: roslaunch
# runs it while loading the launch file, so the bag exists before rosbag play
# starts. Prints the bag's path (the parameter's value); DIR/poses_tum.txt is
# the ground truth, DIR/metadata.json the sensor's metadata.
# usage: write_odometry_bag.sh DIR PRESET FRAMES FORMAT
#   FORMAT: bag (raw Ouster packets, DIR/packets.bag) or points-bag (PointCloud2, DIR/points.bag)
if [ $# -ne 4 ]; then
  echo "usage: write_odometry_bag.sh DIR PRESET FRAMES bag|points-bag" >&2
  exit 2
fi
case "$4" in
  bag) bag="$1/packets.bag" ;;
  points-bag) bag="$1/points.bag" ;;
  *) echo "write_odometry_bag.sh: unknown format '$4' (bag or points-bag)" >&2; exit 2 ;;
esac
rim=$(catkin_find --first-only --libexec range_image_mapping rim)
if [ -z "$rim" ]; then
  echo "write_odometry_bag.sh: rim not found (is the workspace sourced?)" >&2
  exit 1
fi
"$rim" simulate --preset "$2" --frames "$3" --formats "$4" --out "$1" >&2 || exit 1
printf '%s' "$bag"
