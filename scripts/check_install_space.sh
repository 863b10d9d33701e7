#!/usr/bin/env bash
# The package as a user installs it: `catkin_make install` into a temporary
# prefix with testing and benchmarks off, then, with only that install space
# sourced (never the sources or a devel space), a short simulated bag made by
# the installed `rim simulate` is played through
#   roslaunch range_image_mapping range_image_mapping.launch bag_file:=... rviz:=false
# headless, and the check waits for odometry messages. Also checks that the
# configure looked for no test-only package (GTest, OpenSSL, rostest, Google
# Benchmark, OctoMap, PCL) and that no installed file holds the build
# machine's data folder.
#
#   scripts/check_install_space.sh
#
# The build is kept in the ignored .catkin_ws_install/ so a rerun is
# incremental; the install prefix and the bag live in a temporary directory.
# Needs the packages of scripts/setup.sh (python3-nav-msgs for rostopic echo).
# Environment: RIM_INSTALL_CHECK_FRAMES (default 30 scans, 3 s of sensor time).
set -euo pipefail
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

repository=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
workspace=$repository/.catkin_ws_install
frames=${RIM_INSTALL_CHECK_FRAMES:-30}
work=$(mktemp -d /tmp/rim_install_check.XXXXXX)
prefix=$work/install
launch_pid=
started=$SECONDS

cleanup() {
  local status=$?
  if [ -n "$launch_pid" ] && kill -0 -- "-$launch_pid" 2>/dev/null; then
    {
      # The whole process group: roslaunch, its master and nodes are children
      # of the job's shell, and would outlive it.
      kill -INT -- "-$launch_pid" || true
      for _ in $(seq 40); do kill -0 -- "-$launch_pid" || break; sleep 0.5; done
      kill -KILL -- "-$launch_pid" || true
      wait "$launch_pid" || true
    } 2>/dev/null
  fi
  if [ $status != 0 ] && [ -f "$work/launch.log" ]; then
    echo "--- roslaunch output (without rosbag play's progress):"
    tr '\r' '\n' <"$work/launch.log" | grep -v '^ *\[\(RUNNING\|DELAYED\|PAUSED\)\]' | tail -n 40
  fi
  rm -rf "$work"
  echo "== install-space check: $([ $status = 0 ] && echo passed || echo FAILED) in $((SECONDS - started)) s"
  exit $status
}
trap cleanup EXIT
trap 'exit 130' INT TERM

fail() { echo "check_install_space: $*" >&2; exit 1; }

# A clean environment: nothing sourced from the caller (no devel space).
clean_env() {
  env -i HOME="${HOME:-/root}" LANG=C.UTF-8 PATH="$PATH" ROS_HOME="$work/ros" ROS_LOG_DIR="$work/ros/log" "$@"
}

echo "== catkin_make install (CATKIN_ENABLE_TESTING=OFF, RIM_BENCHMARKS=OFF) into $prefix"
mkdir -p "$workspace/src"
ln -sfn "$repository" "$workspace/src/range_image_mapping"
# shellcheck source=compiler_cache.sh
source "$repository/scripts/compiler_cache.sh"
if ! (cd "$workspace" && clean_env CCACHE_BASEDIR="$CCACHE_BASEDIR" CCACHE_DIR="$CCACHE_DIR" catkin_make install \
  -DPYTHON_EXECUTABLE=/usr/bin/python3 "${compiler_cache_options[@]}" \
  -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=OFF -DRIM_BENCHMARKS=OFF \
  -DCMAKE_INSTALL_PREFIX="$prefix" -j2 >"$workspace/build.log" 2>&1); then
  tail -n 60 "$workspace/build.log"
  fail "catkin_make install failed; the whole log is $workspace/build.log"
fi

# No test-only package was looked for (each would leave a found path in the cache).
found=$(grep -E '^(GTest_DIR|GTEST_LIBRARY|OPENSSL_CRYPTO_LIBRARY|rostest_DIR|benchmark_DIR|octomap_DIR|PCL_DIR):' \
  "$workspace/build/CMakeCache.txt" | grep -v -- '-NOTFOUND' || true)
[ -z "$found" ] || fail "the install build looked for test-only packages:"$'\n'"$found"
# No build-machine data folder in an installed file.
data_dir=$(cd "$repository/.." && pwd -P)/shared/data
leaked=$(grep -rl --binary-files=text -F "$data_dir" "$prefix" || true)
[ -z "$leaked" ] || fail "installed files hold the build machine's $data_dir: $leaked"

# From here on only the install space.
run() {
  clean_env bash -c 'set +u; source "$1/setup.bash"; set -u; shift; "$@"' _ "$prefix" "$@"
}
package_dir=$(run rospack find range_image_mapping)
[ "$package_dir" = "$prefix/share/range_image_mapping" ] ||
  fail "rospack finds range_image_mapping at $package_dir, not in the install space"
rim=$prefix/lib/range_image_mapping/rim
[ -x "$rim" ] || fail "no installed rim at $rim"

echo "== rim simulate --preset indoor_cart --frames $frames --formats bag (installed rim)"
run "$rim" simulate --preset indoor_cart --frames "$frames" --formats bag --out "$work/sequence" \
  >"$work/simulate.log" 2>&1 || { cat "$work/simulate.log"; fail "rim simulate failed"; }
bag=$work/sequence/packets.bag
[ -s "$bag" ] || fail "rim simulate wrote no $bag"

# A master of our own on a free port: nothing else on this machine is touched.
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI=http://127.0.0.1:$port
echo "== roslaunch range_image_mapping range_image_mapping.launch rviz:=false (master on port $port)"
# Job control for this one job: it gets a process group of its own (cleanup
# stops the group) and, unlike a plain background job, does not ignore SIGINT,
# which roslaunch needs to shut its nodes and master down.
set -m
clean_env ROS_MASTER_URI="$ROS_MASTER_URI" bash -c \
  'set +u; source "$1/setup.bash"; set -u
   exec roslaunch -p "$2" range_image_mapping range_image_mapping.launch bag_file:="$3" rviz:=false \
     config:="$(rospack find range_image_mapping)/config/os0_128_indoor.yaml"' \
  _ "$prefix" "$port" "$bag" >"$work/launch.log" 2>&1 &
launch_pid=$!
set +m
for _ in $(seq 60); do
  kill -0 "$launch_pid" 2>/dev/null || fail "roslaunch ended before its master came up"
  run env ROS_MASTER_URI="$ROS_MASTER_URI" rostopic list >/dev/null 2>&1 && break
  sleep 1
done

# Three odometry messages within a minute (start-up, 2 s play delay, 3 s of scans).
if ! run env ROS_MASTER_URI="$ROS_MASTER_URI" timeout 60 rostopic echo -n 3 -p /odometry/pose/pose/position \
  >"$work/odometry.csv" 2>"$work/rostopic.log"; then
  cat "$work/rostopic.log"
  fail "no odometry on /odometry within 60 s"
fi
messages=$(grep -c -v '^%' "$work/odometry.csv" || true)
[ "$messages" -ge 3 ] || fail "only $messages odometry messages arrived"
kill -0 "$launch_pid" 2>/dev/null || fail "roslaunch ended early"
echo "   $messages odometry messages from the installed launch; last position:" \
  "$(tail -n 1 "$work/odometry.csv" | cut -d, -f2-4)"
