#!/bin/bash
# A screenshot of rviz/mapping.rviz while mapping.launch maps a simulated
# sequence: simulates indoor_cart (rim simulate, raw Ouster packets in a bag),
# starts a virtual X server (Xvfb :99, software OpenGL) and a ROS master of its
# own, replays the bag through the Adapter, Odometry and Mapper with rviz, waits
# until the replay is over and the mesh has grown, captures the screen and
# cleans everything up.
#
# usage: scripts/screenshot_rviz.sh [OUT.png]   (default out/rviz_mapping.png)
# Needs the workspace sourced (devel/setup.bash), Xvfb and ImageMagick's import.
# Environment: FRAMES (default 60), PRESET (indoor_cart), RATE (0.25),
# ENVIRONMENT (indoor), RVIZ_CONFIG (rviz/mapping.rviz; rviz/mapping_outdoor.rviz
# follows the sensor from farther away), DISPLAY_NUMBER (99), ROS_PORT (11399),
# KEEP_LOGS (unset: the temporary folder with the sequence and the logs is
# removed). The README's outdoor screenshot:
#   PRESET=outdoor_car FRAMES=300 ENVIRONMENT=outdoor RVIZ_CONFIG=rviz/mapping_outdoor.rviz \
#     scripts/screenshot_rviz.sh doc/rviz_outdoor_live_mesh.png
set -euo pipefail

out=${1:-out/rviz_mapping.png}
frames=${FRAMES:-60}
preset=${PRESET:-indoor_cart}
rate=${RATE:-0.25}
environment=${ENVIRONMENT:-indoor}
rviz_config=${RVIZ_CONFIG:-}
display_number=${DISPLAY_NUMBER:-99}
ros_port=${ROS_PORT:-11399}

fail() {
  echo "screenshot_rviz.sh: $*" >&2
  exit 1
}
for tool in Xvfb import roslaunch rosservice catkin_find; do
  command -v "$tool" >/dev/null || fail "$tool not found (Xvfb, imagemagick, a sourced ROS workspace)"
done
rim=$(catkin_find --first-only --libexec range_image_mapping rim) ||
  fail "rim not found: source the workspace's devel/setup.bash first"
[ -n "$rim" ] || fail "rim not found: source the workspace's devel/setup.bash first"
[ -e "/tmp/.X${display_number}-lock" ] &&
  fail "display :${display_number} is in use (/tmp/.X${display_number}-lock); set DISPLAY_NUMBER"
mkdir -p "$(dirname "$out")"
out=$(realpath "$out")
if [ -n "$rviz_config" ]; then
  [ -f "$rviz_config" ] || fail "RVIZ_CONFIG $rviz_config does not exist"
  rviz_config=$(realpath "$rviz_config")
fi

work=$(mktemp -d /tmp/rim_screenshot.XXXXXX)
xvfb_pid=""
launch_pid=""
cleanup() {
  # Only the processes started here, by their ids: roslaunch stops its nodes
  # (and its master) on SIGINT.
  if [ -n "$launch_pid" ] && kill -0 "$launch_pid" 2>/dev/null; then
    kill -INT "$launch_pid" 2>/dev/null || true
    for _ in $(seq 1 30); do kill -0 "$launch_pid" 2>/dev/null || break; sleep 0.5; done
    kill -KILL "$launch_pid" 2>/dev/null || true
  fi
  if [ -n "$xvfb_pid" ]; then kill "$xvfb_pid" 2>/dev/null || true; fi
  if [ -n "${KEEP_LOGS:-}" ]; then echo "logs kept in $work" >&2; else rm -rf "$work"; fi
}
trap cleanup EXIT

echo "simulating $frames frames of $preset ..."
"$rim" simulate --preset "$preset" --frames "$frames" --formats bag --out "$work/sequence" >"$work/simulate.log" 2>&1 ||
  { cat "$work/simulate.log" >&2; fail "rim simulate failed"; }

Xvfb ":${display_number}" -screen 0 1600x1000x24 -nolisten tcp >"$work/xvfb.log" 2>&1 &
xvfb_pid=$!
sleep 2
kill -0 "$xvfb_pid" 2>/dev/null || { cat "$work/xvfb.log" >&2; fail "Xvfb did not start"; }

export DISPLAY=":${display_number}" LIBGL_ALWAYS_SOFTWARE=1
export ROS_MASTER_URI="http://localhost:${ros_port}"
export ROS_LOG_DIR="$work/ros_log"
echo "replaying through mapping.launch with rviz (log: $work/launch.log) ..."
roslaunch -p "$ros_port" range_image_mapping mapping.launch bag_file:="$work/sequence/packets.bag" \
  rate:="$rate" environment:="$environment" rviz:=true ${rviz_config:+rviz_config:="$rviz_config"} \
  >"$work/launch.log" 2>&1 &
launch_pid=$!

# The replay is over when roslaunch reports that rosbag play has finished.
finished=false
for _ in $(seq 1 900); do
  kill -0 "$launch_pid" 2>/dev/null || { tail -30 "$work/launch.log" >&2; fail "roslaunch exited"; }
  if grep -q 'rosbag_play-[0-9]*\] process has finished' "$work/launch.log"; then
    finished=true
    break
  fi
  sleep 1
done
$finished || fail "the replay did not finish within 15 minutes (see $work/launch.log)"

# The mesh has grown: the Mapper saves a non-empty mesh (saving meshes first).
saved=$(rosservice call /mapper/save_mesh "path: '$work/mesh.ply'" 2>&1) || fail "save_mesh: $saved"
echo "$saved" | grep -q "success: True" || fail "no mesh: $saved"
echo "$saved" | grep message
sleep 6  # two mesh updates and a few rviz frames

DISPLAY=":${display_number}" import -window root "$out"
echo "screenshot: $out"
grep -o 'mapper: .*triangles ([0-9]* shown)[^"]*' "$work/launch.log" | tail -1 || true
