#!/bin/sh
# Writes the sequence of stationary_sensor.test, for its <param command=...>:
# roslaunch runs it while loading the launch file, so the bag exists before
# rosbag play starts. Prints DIR (the parameter's value).
#
# A stationary OS0-128 in the indoor scene whose attitude wanders by 1e-9 to
# 2e-8 rad per scan: the range of rotations where the SE(3) logarithm once
# divided by 1 - cos(angle) = 0 (a real Velodyne recording ran to a NaN
# translation and a pose 150 m away). DIR/stationary_poses_tum.txt is the
# TUM pose file (T_world_os_lidar), 12 s at 10 ms, written here and
# interpolated by rim simulate:
#   position  fixed, 1.2 m above the floor, at the corner of the corridor ring
#             of the seed-1 indoor scene (walls along both axes: no direction
#             the registration cannot see)
#   yaw(t)  = 1.5e-7 rad/s * t        (1.5e-8 rad per 0.1 s scan)
#   roll(t) = 5e-8 rad * sin(0.5 t)   (at most 2.5e-9 rad per scan)
# Noise-free ranges (--noise 0): with the default 1 cm noise the odometry's
# per-scan rotations are ~1e-5 rad, far from the critical range; noise-free,
# most of them land in it (see stationary_sensor.cpp).
# usage: write_stationary_sequence.sh DIR FRAMES
if [ $# -ne 2 ]; then
  echo "usage: write_stationary_sequence.sh DIR FRAMES" >&2
  exit 2
fi
rim=$(catkin_find --first-only --libexec range_image_mapping rim)
if [ -z "$rim" ]; then
  echo "write_stationary_sequence.sh: rim not found (is the workspace sourced?)" >&2
  exit 1
fi
mkdir -p "$1" || exit 1
poses="$1/stationary_poses_tum.txt"
/usr/bin/env python3 - "$poses" <<'EOF' || exit 1
import math, sys
x, y, z = 11.235, 11.235, 1.2
with open(sys.argv[1], "w") as out:
    out.write("# stationary sensor, attitude wandering by 1e-9..2e-8 rad per scan: time tx ty tz qx qy qz qw\n")
    for i in range(1201):
        t = i * 0.01
        yaw, roll = 1.5e-7 * t, 5e-8 * math.sin(0.5 * t)
        cy, sy, cr, sr = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
        # q = q_yaw(z) * q_roll(x); repr keeps every digit of the tiny parts
        out.write(f"{t:.2f} {x!r} {y!r} {z!r} {cy * sr!r} {sy * sr!r} {sy * cr!r} {cy * cr!r}\n")
EOF
"$rim" simulate --sensor OS-0-128 --scene indoor --seed 1 --motion "$poses" --noise 0 \
  --frames "$2" --formats bag --out "$1" >&2 || exit 1
printf '%s' "$1"
