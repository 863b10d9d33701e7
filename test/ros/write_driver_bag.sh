#!/bin/sh
# Runs driver_bag_node --write-bag from this package's devel or install space,
# for the <param command=...> of driver_bag.test (the bag exists before
# rosbag play starts).
node=$(catkin_find --first-only --libexec range_image_mapping driver_bag_node)
if [ -z "$node" ]; then
  echo "write_driver_bag.sh: driver_bag_node not found (is the workspace sourced?)" >&2
  exit 1
fi
exec "$node" --write-bag "$@"
