#!/bin/sh
# Writes a simulated sequence with rim simulate from this package's devel or
# install space, for the <param command=...> of the zero_copy,
# fault_injection and run_matches_nodelets tests: roslaunch runs it while
# loading the launch file, so the files exist before anything reads them.
# Prints DIR (the parameter's value).
# usage: write_sequence.sh DIR PRESET FRAMES FORMATS
#   FORMATS: rim simulate's, comma-separated (pcap, bag, points-bag, kitti)
if [ $# -ne 4 ]; then
  echo "usage: write_sequence.sh DIR PRESET FRAMES FORMATS" >&2
  exit 2
fi
rim=$(catkin_find --first-only --libexec range_image_mapping rim)
if [ -z "$rim" ]; then
  echo "write_sequence.sh: rim not found (is the workspace sourced?)" >&2
  exit 1
fi
"$rim" simulate --preset "$2" --frames "$3" --formats "$4" --out "$1" >&2 || exit 1
printf '%s' "$1"
