#!/usr/bin/env bash
# The README's main job on the Noetic-era toolchain: Debian bullseye (ros_comm
# 1.15 as in ROS Noetic, GCC 10, CMake 3.18, PCL 1.11, TBB 2020, Eigen 3.3.9,
# Boost 1.74, nanoflann 1.3.2) in a chroot, as root.
#
#   scripts/check_noetic_toolchain.sh
#
# 1. Makes a bullseye chroot with debootstrap (installed with apt if missing)
#    from the Debian mirror this machine's apt already uses (read from
#    /etc/apt/sources.list.d/*.sources or /etc/apt/sources.list at run time),
#    cached in the ignored .noetic_chroot/ (rootfs/, and the chroot's own
#    catkin workspace and demo output), so a rerun is fast.
# 2. Bind-mounts the repository (at the same path) and ../shared read-only if
#    present, so the data tests run; the chroot's .catkin_ws/ and out/ are its
#    own (.noetic_chroot/catkin_ws, .noetic_chroot/out), never the host's.
# 3. Inside: `bash scripts/setup.sh demo` (installs the Debian packages, builds
#    with catkin_make, runs the demo) with RIM_BENCHMARKS=0 (lean: no benchmark
#    programs, no PCL or Google Benchmark), then builds the unit tests (the
#    `rim_unit_tests` target: every gtest, not the rostest nodes) and runs them
#    with ctest, excluding
#      * the rostests (_rostest_): they start roscore and nodelet managers and
#        replay bags in real time, and test ros_comm behaviour rather than the
#        toolchain;
#      * the fuzzers (fuzz_ouster_inputs): a separate clang build of their own
#        that runs each fuzzer for a minute and writes build-fuzz/ into the
#        (shared) repository;
#      * preset_accuracy_test, mapping_accuracy_test and
#        simulated_sensors_test: accuracy figures over whole simulated
#        sequences (OctoMap comparisons included), 25 min and more together
#        here, where bullseye's Embree 3.12 casts rays several times slower
#        than bookworm's; the same code paths (surface metrics, rim
#        run/map/eval, the TSDF, the sensor catalog) are run by the other unit
#        tests.
#    RIM_CHROOT_ALL_UNIT_TESTS=1 runs those as well.
# Prints the time each step took. Everything runs in a private mount
# namespace; /proc, /sys, /dev and the binds are unmounted on exit.
# Exit status 77 (and a message saying why) when this machine cannot host the
# chroot at all: no mount namespace (no CAP_SYS_ADMIN) or the mirror cannot
# be reached; .ci/run reports that as skipped. Everything after the chroot
# exists (packages, build, demo, tests) fails with its own status.
# Environment: RIM_CHROOT_DIR (default .noetic_chroot), RIM_CHROOT_ALL_UNIT_TESTS=1,
# RIM_CHROOT_CTEST_ARGS (extra ctest arguments, e.g. "-R lidar_model").
set -euo pipefail
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

suite=bullseye
repository=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
cache=${RIM_CHROOT_DIR:-$repository/.noetic_chroot}
root=$cache/rootfs
shared=$(cd "$repository/.." && pwd -P)/shared

[ "$(id -u)" = 0 ] || { echo "$0: run as root (debootstrap, chroot, mount)" >&2; exit 2; }

# A private mount namespace: nothing mounted here is seen by (or left behind
# on) the host, even if this script is killed.
if [ -z "${RIM_CHROOT_NAMESPACE:-}" ]; then
  unshare --mount true 2>/dev/null || {
    echo "$0: cannot make a mount namespace here (needs CAP_SYS_ADMIN): no chroot check on this machine" >&2
    exit 77
  }
  export RIM_CHROOT_NAMESPACE=1
  exec unshare --mount --propagation private bash "$0" "$@"
fi

started=$SECONDS
step_started=$SECONDS
step() {
  echo "== [$(((SECONDS - started) / 60))m$(((SECONDS - started) % 60))s] $*"
  step_started=$SECONDS
}
step_done() { echo "   took $((SECONDS - step_started)) s"; }

# ---------------------------------------------------------------- mirror
# The URIs this machine's apt uses: deb822 URIs: fields, then one-line sources.
apt_uris() {
  local file
  for file in /etc/apt/sources.list.d/*.sources; do
    [ -f "$file" ] && awk '/^URIs:/ {for (i = 2; i <= NF; i++) print $i}' "$file"
  done
  for file in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [ -f "$file" ] && sed -E 's/#.*//; s/\[[^]]*\]//g' "$file" | awk '$1 == "deb" {print $2}'
  done
  return 0
}
mirror=$(apt_uris | grep -v -- '-security' | grep -E '/debian/?$' | head -n 1 || true)
[ -n "$mirror" ] || mirror=$(apt_uris | grep -v -- '-security' | head -n 1 || true)
if [ -z "$mirror" ]; then
  echo "$0: no Debian mirror found in /etc/apt/sources.list.d/*.sources or /etc/apt/sources.list" >&2
  exit 1
fi

mkdir -p "$cache"
exec 9>"$cache/lock"
flock -n 9 || { echo "$0: another run holds $cache/lock" >&2; exit 1; }

# ---------------------------------------------------------------- chroot
if [ ! -f "$root/.rim_bootstrap_complete" ]; then
  step "debootstrap $suite into $root (from $mirror)"
  command -v debootstrap >/dev/null || {
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap >/dev/null
  }
  if [ -e "$root" ]; then
    # An interrupted bootstrap: start over, but never through a mount point.
    if findmnt -rn -o TARGET | grep -q "^$root/"; then
      echo "$0: something is mounted under $root; not removing it" >&2
      exit 1
    fi
    rm -rf --one-file-system "$root"
  fi
  debootstrap --variant=minbase --include=ca-certificates "$suite" "$root" "$mirror" \
    >"$cache/debootstrap.log" 2>&1 || {
    tail -n 30 "$cache/debootstrap.log"
    echo "$0: debootstrap of $suite from $mirror failed (no network, or the mirror has no $suite)" >&2
    exit 77
  }
  touch "$root/.rim_bootstrap_complete"
  step_done
fi

# apt sources written from this run's mirror (the release and its point
# updates; not $suite-security, whose pool mirrors do not reliably carry and
# the toolchain check does not need); no service starts in the chroot.
{
  echo "deb $mirror $suite main"
  echo "deb $mirror $suite-updates main"
} >"$root/etc/apt/sources.list"
printf '#!/bin/sh\nexit 101\n' >"$root/usr/sbin/policy-rc.d"
chmod 755 "$root/usr/sbin/policy-rc.d"
cp -L /etc/resolv.conf "$root/etc/resolv.conf"
find "$root/tmp" -mindepth 1 -delete 2>/dev/null || true

# ---------------------------------------------------------------- mounts
mounted=()
cleanup() {
  local status=$? index
  for ((index = ${#mounted[@]} - 1; index >= 0; index--)); do
    umount -R "${mounted[index]}" 2>/dev/null || umount -l "${mounted[index]}" 2>/dev/null || true
  done
  echo "== noetic toolchain check: $([ $status = 0 ] && echo passed || echo FAILED) in" \
    "$(((SECONDS - started) / 60)) min $(((SECONDS - started) % 60)) s"
  exit $status
}
trap cleanup EXIT
trap 'exit 130' INT TERM

bind() {  # bind SOURCE TARGET [ro]
  mkdir -p "$2"
  mount --bind "$1" "$2"
  mounted+=("$2")
  [ "${3:-}" != ro ] || mount -o remount,bind,ro "$2"
}
mount -t proc proc "$root/proc"
mounted+=("$root/proc")
mount --rbind /sys "$root/sys"
mounted+=("$root/sys")
mount --rbind /dev "$root/dev"
mounted+=("$root/dev")
bind "$repository" "$root$repository"
mkdir -p "$cache/catkin_ws" "$cache/out"
bind "$cache/catkin_ws" "$root$repository/.catkin_ws"
bind "$cache/out" "$root$repository/out"
if [ -d "$shared" ]; then
  bind "$shared" "$root$shared" ro
else
  echo "   no $shared: tests that need the real data skip"
fi

in_chroot() {
  chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM=dumb \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    ROS_HOME=/tmp/ros ROS_LOG_DIR=/tmp/ros/log RIM_BENCHMARKS=0 RIM_DATA_DIR="$shared/data" \
    bash -c "set -euo pipefail; cd '$repository'; $1"
}

# ---------------------------------------------------------------- the check
step "toolchain: $(chroot "$root" bash -c '. /etc/os-release; echo "$PRETTY_NAME"')"
step "bash scripts/setup.sh demo (in the chroot)"
in_chroot "bash scripts/setup.sh demo"
chroot "$root" apt-get clean
step_done
echo "   versions: $(in_chroot "dpkg-query -W -f='\${Package} \${Version}, ' g++ cmake catkin python3-rosbag \
  libeigen3-dev libtbb-dev libboost-dev libnanoflann-dev libembree-dev libpcl-dev 2>/dev/null || true")"

step "unit tests: build (catkin_make rim_unit_tests)"
in_chroot "cd .catkin_ws && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 -j2 rim_unit_tests >build_tests.log 2>&1 ||
  { tail -n 60 build_tests.log; exit 1; }"
step_done
excluded='_rostest_|^fuzz_|_preset_accuracy_test$|_mapping_accuracy_test$|_simulated_sensors_test$'
[ "${RIM_CHROOT_ALL_UNIT_TESTS:-0}" = 1 ] && excluded='_rostest_|^fuzz_'
step "unit tests: ctest -E '$excluded' (see the header for why)"
in_chroot "set +u; source .catkin_ws/devel/setup.bash; set -u; cd .catkin_ws/build &&
  ctest -j2 --output-on-failure -E '$excluded' ${RIM_CHROOT_CTEST_ARGS:-}"
step_done
