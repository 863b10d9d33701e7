#!/bin/bash
# Memory of the nodelet manager over a long simulated drive: rim simulate
# writes an outdoor_car sequence (raw packets in a bag), range_image_mapping.launch
# replays it with the outdoor config and memory_radius set, and the manager's
# resident memory (VmRSS) is sampled every few seconds. Prints the figures
# and whether the second half is flat; writes rss.csv (seconds, MiB) and the
# launch log into the work folder.
#
# usage: scripts/memory_soak.sh [--frames N] [--rate R] [--memory-radius M]
#                               [--keep-dropped-mesh true|false] [--work DIR] [--keep]
#   --frames          simulated scans (default 900: 90 s of driving, about 600 m)
#   --rate            playback rate (default 0.4: the odometry keeps up on 2 shared cores)
#   --memory-radius   the Mapper's memory_radius, m (default 40; the outdoor range clip is 30)
#   --keep-dropped-mesh  the Mapper's keep_dropped_mesh (default false: flat memory)
#   --work            work folder (default: a new one under /tmp); --keep leaves it
# Needs the catkin workspace sourced (rim, the nodelets, roslaunch).
set -euo pipefail

frames=900
rate=0.4
memory_radius=40
keep_dropped_mesh=false
work=""
keep=false
while [ $# -gt 0 ]; do
  case "$1" in
    --frames) frames="$2"; shift 2 ;;
    --rate) rate="$2"; shift 2 ;;
    --memory-radius) memory_radius="$2"; shift 2 ;;
    --keep-dropped-mesh) keep_dropped_mesh="$2"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --keep) keep=true; shift ;;
    *) echo "memory_soak.sh: unknown argument '$1' (see the header of this script)" >&2; exit 2 ;;
  esac
done

fail() { echo "memory_soak.sh: $*" >&2; exit 1; }
command -v roslaunch >/dev/null || fail "roslaunch not found: source the catkin workspace first"
rim=$(catkin_find --first-only --libexec range_image_mapping rim) || true
[ -n "$rim" ] || fail "rim not found: source the catkin workspace first"

[ -n "$work" ] || work=$(mktemp -d /tmp/rim_memory_soak.XXXXXX)
mkdir -p "$work"
launch_pid=""
cleanup() {
  # Only what this script started, by its id.
  if [ -n "$launch_pid" ] && kill -0 "$launch_pid" 2>/dev/null; then
    kill -INT "$launch_pid" 2>/dev/null || true
    for _ in $(seq 1 30); do kill -0 "$launch_pid" 2>/dev/null || break; sleep 1; done
    kill -KILL "$launch_pid" 2>/dev/null || true
  fi
  if [ "$keep" = false ]; then rm -rf "$work/sequence"; fi
}
trap cleanup EXIT

# Raw packets in the small profile: a third of the default's bytes.
if [ ! -f "$work/sequence/packets.bag" ]; then
  echo "simulating $frames outdoor_car scans into $work/sequence ..."
  "$rim" simulate --preset outdoor_car --frames "$frames" --formats bag --profile RNG15_RFL8_NIR8 \
    --out "$work/sequence" >"$work/simulate.log" 2>&1 || { tail -5 "$work/simulate.log" >&2; fail "rim simulate failed"; }
fi

cat >"$work/soak.yaml" <<EOF
mapper:
  memory_radius: $memory_radius
  keep_dropped_mesh: $keep_dropped_mesh
EOF

# A master of our own, so nothing else on the machine is disturbed.
port=$((20000 + RANDOM % 20000))
export ROS_MASTER_URI="http://localhost:$port"
export ROS_LOG_DIR="$work/ros_log"
echo "replaying at rate $rate through range_image_mapping.launch (memory_radius $memory_radius m, log $work/launch.log) ..."
roslaunch -p "$port" range_image_mapping range_image_mapping.launch bag_file:="$work/sequence/packets.bag" \
  rate:="$rate" config:="$(rospack find range_image_mapping)/config/os1_128_outdoor.yaml" \
  extra_config:="$work/soak.yaml" >"$work/launch.log" 2>&1 &
launch_pid=$!

manager_pid=""
for _ in $(seq 1 60); do
  manager_pid=$(rosnode info /rim_manager 2>/dev/null | sed -n 's/^Pid: \([0-9]*\)$/\1/p') || true
  [ -n "$manager_pid" ] && break
  kill -0 "$launch_pid" 2>/dev/null || { tail -20 "$work/launch.log" >&2; fail "roslaunch exited"; }
  sleep 1
done
[ -n "$manager_pid" ] || fail "no /rim_manager after 60 s"

echo "seconds,rss_mib" >"$work/rss.csv"
start=$(date +%s)
while kill -0 "$manager_pid" 2>/dev/null; do
  rss_kib=$(sed -n 's/^VmRSS:[[:space:]]*\([0-9]*\) kB$/\1/p' "/proc/$manager_pid/status" 2>/dev/null) || break
  echo "$(( $(date +%s) - start )),$(awk -v k="$rss_kib" 'BEGIN { printf "%.1f", k / 1024 }')" >>"$work/rss.csv"
  grep -q 'rosbag_play-[0-9]*\] process has finished' "$work/launch.log" && break
  sleep 5
done
sleep 5  # the last scans
grep -q 'rosbag_play-[0-9]*\] process has finished' "$work/launch.log" || fail "the manager died before the replay ended (see $work/launch.log)"

# Figures: RSS at a quarter, half and the end, the peak, and the slope of a
# least-squares line over the second half (MiB per minute).
awk -F, -v frames="$frames" -v rate="$rate" -v radius="$memory_radius" 'NR > 1 { t[n] = $1; m[n] = $2; n++ }
  END {
    if (n < 8) { print "too few samples (" n ")"; exit 1 }
    peak = 0; for (i = 0; i < n; i++) if (m[i] > peak) peak = m[i]
    h = int(n / 2); sx = sy = sxx = sxy = 0; k = n - h
    for (i = h; i < n; i++) { sx += t[i]; sy += m[i]; sxx += t[i] * t[i]; sxy += t[i] * m[i] }
    slope = (k * sxy - sx * sy) / (k * sxx - sx * sx) * 60
    printf "%d scans at rate %s, memory_radius %s m: %d samples over %d s\n", frames, rate, radius, n, t[n - 1]
    printf "RSS: %.0f MiB at 1/4, %.0f MiB at 1/2, %.0f MiB at the end, peak %.0f MiB\n", m[int(n / 4)], m[h], m[n - 1], peak
    printf "second half: %+.2f MiB per minute (%s)\n", slope, (slope < 1.0 && slope > -1.0 ? "flat" : "not flat")
  }' "$work/rss.csv" | tee "$work/summary.txt"
# The nodelets' last statistics lines (colour codes and rosbag's progress stripped).
for nodelet in mapper odometry; do
  tr '\r' '\n' <"$work/launch.log" | sed 's/\x1b\[[0-9;]*m//g' | grep -o "$nodelet: [0-9.]* Hz.*" | tail -1 |
    sed "s/^/last /" || true
done
echo "samples: $work/rss.csv"
