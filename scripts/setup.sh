#!/usr/bin/env bash
# One-command set-up for a fresh Debian bookworm machine, as root.
#   scripts/setup.sh demo   install, build, run the main job
#   scripts/setup.sh test   install, build, run every test (unit, rostest, fuzzers)
# Also Debian bullseye (the Noetic-era toolchain; scripts/check_noetic_toolchain.sh).
# Environment: RIM_DATA_DIR (default: ../shared/data next to the repository),
#              RIM_FUZZ_SECONDS (default 60 per fuzzer), RIM_SKIP_INSTALL=1,
#              RIM_BENCHMARKS=0 (no benchmark programs, nor the packages only they need).
set -euo pipefail

mode=${1:-}
case "$mode" in demo | test) ;; *) echo "usage: $0 demo|test" >&2; exit 2 ;; esac

repository=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
workspace="$repository/.catkin_ws"
export RIM_DATA_DIR=${RIM_DATA_DIR:-$(cd "$repository/.." && pwd)/shared/data}
# catkin needs Debian's python3 (with catkin_pkg), not a pyenv shim earlier on PATH.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

packages=(
  build-essential cmake pkg-config git
  catkin ros-core-dev rosbash python3-roslaunch python3-rostest python3-rosbag rviz
  python3-nav-msgs python3-geometry-msgs  # rostopic echo of odometry (check_install_space.sh)
  libnodeletlib-dev libnodeletlib-tools libnodelet-dev pluginlib-dev libtopic-tools-dev
  libtf2-ros-dev libtf2-eigen-dev libsensor-msgs-dev libnav-msgs-dev libvisualization-msgs-dev
  librostest-dev libgtest-dev
  libeigen3-dev libtbb-dev libjsoncpp-dev libyaml-cpp-dev libpcap-dev libboost-program-options-dev libpng-dev libssl-dev
  libnanoflann-dev libembree-dev robin-map-dev gnuplot-nox clang liboctomap-dev
  libstd-srvs-dev libdiagnostic-updater-dev libboost-dev
)
# Only the benchmark programs need these (PCL: the ICP/GICP baselines;
# OpenVDB: VDBFusion from ../shared/peers, vdbfusion_comparison_benchmark).
benchmarks=${RIM_BENCHMARKS:-1}
[ "$benchmarks" = 0 ] || packages+=(libbenchmark-dev libpcl-dev libopenvdb-dev)
# The test run's objects are cached, so that scripts/check_install_space.sh
# (CI's next step, a second workspace with the same flags) compiles nothing twice.
[ "$mode" = test ] && packages+=(ccache)

install_dependencies() {
  [ "${RIM_SKIP_INSTALL:-0}" = 1 ] && return
  local missing=()
  for package in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed" ||
      missing+=("$package")
  done
  [ ${#missing[@]} -eq 0 ] && return
  echo "== installing ${#missing[@]} Debian packages"
  apt-get update -qq
  # One message naming every package this Debian release lacks, not apt's first.
  local unavailable=()
  for package in "${missing[@]}"; do
    local candidate
    candidate=$(apt-cache policy "$package" 2>/dev/null | awk '/Candidate:/ {print $2}')
    [ -n "$candidate" ] && [ "$candidate" != "(none)" ] || unavailable+=("$package")
  done
  if [ ${#unavailable[@]} -gt 0 ]; then
    echo "not available on this Debian release ($(. /etc/os-release && echo "$VERSION_CODENAME")):" \
      "${unavailable[*]}" >&2
    exit 1
  fi
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

build() {
  echo "== building in $workspace"
  mkdir -p "$workspace/src"
  ln -sfn "$repository" "$workspace/src/range_image_mapping"
  # Test binaries are built by catkin's `tests` target (as catkin_add_gtest's are).
  local targets=(all)
  [ "$mode" = test ] && targets+=(tests)
  local benchmark_option=ON
  [ "$benchmarks" = 0 ] && benchmark_option=OFF
  # shellcheck source=compiler_cache.sh
  source "$repository/scripts/compiler_cache.sh"
  if ! (cd "$workspace" && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DCMAKE_BUILD_TYPE=Release -DRIM_BENCHMARKS=$benchmark_option "${compiler_cache_options[@]}" \
    -j2 "${targets[@]}" \
    >"$workspace/build.log" 2>&1); then
    tail -n 60 "$workspace/build.log"
    echo "build failed; the whole log is $workspace/build.log" >&2
    exit 1
  fi
}

ros_environment() {
  set +u
  # shellcheck disable=SC1091
  source "$workspace/devel/setup.bash"
  set -u
}

demo() {
  ros_environment
  # The main job on data the project makes itself: a short OS0-128 sequence
  # from the simulator (exact ground truth), odometry and TSDF mapping with
  # rim run, scored against the truth. --bag also writes the packets for the
  # rviz replay printed at the end.
  local out="$repository/out/demo"
  rm -rf "$out"
  "$workspace/devel/lib/range_image_mapping/rim" run indoor_cart --frames 100 --bag --out "$out"
  echo
  echo "Watch the same data grow into a mesh in rviz:"
  echo "  source $workspace/devel/setup.bash"
  echo "  roslaunch range_image_mapping range_image_mapping.launch bag_file:=$out/sequence/packets.bag \\"
  echo "    config:=\$(rospack find range_image_mapping)/config/os0_128_indoor.yaml rviz:=true"
}

run_tests() {
  ros_environment
  # One runner for everything: gtests, rostests and the fuzzer runs are ctest tests,
  # two at a time (the tests that keep both cores busy claim both: CMakeLists.txt).
  echo "== tests"
  cd "$workspace/build"
  local started
  started=$(date +%s)
  if ! ctest -j2 --output-on-failure; then
    # The reasons last, where a log's tail shows them.
    /usr/bin/python3 "$repository/scripts/test_failures.py" test_results --since "$started"
    return 1
  fi
}

install_dependencies
build
if [ "$mode" = demo ]; then demo; else run_tests; fi
