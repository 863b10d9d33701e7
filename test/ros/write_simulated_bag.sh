#!/bin/sh
# Runs simulated_bag_node from this package's devel or install space, for the
# <param command=...> of simulated_bag.test: roslaunch runs it while loading
# the launch file, so the bag exists before rosbag play starts.
node=$(catkin_find --first-only --libexec range_image_mapping simulated_bag_node)
if [ -z "$node" ]; then
  echo "write_simulated_bag.sh: simulated_bag_node not found (is the workspace sourced?)" >&2
  exit 1
fi
exec "$node" --write-bag "$@"
