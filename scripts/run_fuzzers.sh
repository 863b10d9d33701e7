#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan + UBSan) in build-fuzz/ and runs
# each for SECONDS (default 60). Seeds come from the real captures when the
# shared data is there (extracted into a temporary directory, never into the
# repository). Exits non-zero if a fuzzer finds a crash, leak or sanitizer
# report; the reproducer is kept in build-fuzz/artifacts/.
#
#   scripts/run_fuzzers.sh [SECONDS]
set -euo pipefail

seconds="${1:-60}"
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || [ "$seconds" -lt 1 ]; then
  echo "usage: $0 [SECONDS]  (seconds per fuzzer, default 60)" >&2
  exit 2
fi
repository="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
build="$repository/build-fuzz"
data="${RIM_DATA_DIR:-$repository/../shared/data}"
captures="$data/ouster-pcaps"
fuzzers=(ouster_packet_fuzzer ouster_metadata_fuzzer)

cmake -S "$repository" -B "$build" -DRIM_FUZZ=ON -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_C_COMPILER=clang -DRIM_CORE_ONLY=ON -DBUILD_TESTING=OFF -DRIM_BENCHMARKS=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPYTHON_EXECUTABLE=/usr/bin/python3 >/dev/null
cmake --build "$build" -j2 --target "${fuzzers[@]}" >/dev/null

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$build/artifacts"
for fuzzer in "${fuzzers[@]}"; do mkdir -p "$work/$fuzzer/seeds" "$work/$fuzzer/corpus"; done

# Packet seeds: real payloads in the fuzzer's input form (layout byte, then an
# operation byte 0 before each packet). Layout indices follow kLayouts in
# fuzz/ouster_packet_fuzzer.cpp.
if [ -d "$captures" ]; then
  python3 - "$captures" "$work/ouster_packet_fuzzer/seeds" <<'PYTHON'
import os, struct, sys

captures, seeds = sys.argv[1], sys.argv[2]
layouts = {  # capture -> layout index of the fuzzer
    "OS-1-32-G_v2.1.1_1024x10.pcap": 1, "OS-2-32-U0_v2.0.0_1024x10.pcap": 1,
    "OS-1-64_1024x10_fw20.pcap": 2, "OS-2-128-U1_v2.3.0_1024x10.pcap": 3,
    "OS-0-32-U1_v2.2.0_1024x10.pcap": 4, "OS-1-128_v2.3.0_1024x10_lb_n3.pcap": 5,
    "OS-0-128-U1_v2.3.0_1024x10.pcap": 5, "crc_test.pcap": 6, "windowed_frame2.pcap": 6,
}

def udp_payloads(path):
    """UDP payloads of a classic little-endian Ethernet/IPv4 pcap."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] not in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1"):
        return []
    payloads, at = [], 24
    while at + 16 <= len(data):
        captured = struct.unpack_from("<I", data, at + 8)[0]
        frame = data[at + 16:at + 16 + captured]
        at += 16 + captured
        if len(frame) < 42 or frame[12:14] != b"\x08\x00":
            continue
        header = (frame[14] & 15) * 4
        payloads.append(frame[14 + header + 8:])
    return payloads

for name, layout in layouts.items():
    path = os.path.join(captures, name)
    if not os.path.exists(path):
        continue
    payloads = udp_payloads(path)
    size = max(len(p) for p in payloads)  # lidar packets are the big ones
    lidar = [p for p in payloads if len(p) == size]
    # First two packets, and the last of a frame with the first of the next.
    for index, chosen in enumerate([lidar[0:2], lidar[63:65], lidar[-2:]]):
        if not chosen:
            continue
        seed = bytes([layout]) + b"".join(b"\x00" + p for p in chosen)
        with open(os.path.join(seeds, f"{name}.{index}"), "wb") as f:
            f.write(seed)
PYTHON
  cp "$captures"/*.json "$work/ouster_metadata_fuzzer/seeds/" 2>/dev/null || true
  rm -f "$work/ouster_metadata_fuzzer/seeds/"*_digest.json
else
  echo "note: $captures not found; fuzzing without real seeds" >&2
fi
# A few hand-made seeds so the fuzzers have a start without the data too.
printf '\005\000' >"$work/ouster_packet_fuzzer/seeds/empty_packet"
printf '{"lidar_mode": "1024x10", "beam_altitude_angles": [1, 0], "beam_azimuth_angles": [0, 0]}' \
  >"$work/ouster_metadata_fuzzer/seeds/minimal.json"
printf '{"beam_intrinsics": {"beam_altitude_angles": [1], "beam_azimuth_angles": [0]}, "config_params": {"lidar_mode": "512x10", "udp_profile_lidar": "RNG15_RFL8_NIR8"}, "lidar_data_format": {"column_window": [400, 20]}}' \
  >"$work/ouster_metadata_fuzzer/seeds/nested.json"
# The metadata keys, so mutations reach past the JSON syntax.
dictionary="$work/metadata.dict"
for key in beam_intrinsics beam_altitude_angles beam_azimuth_angles lidar_origin_to_beam_origin_mm \
  beam_to_lidar_transform lidar_data_format data_format columns_per_frame columns_per_packet \
  column_window pixels_per_column pixel_shift_by_row udp_profile_lidar config_params lidar_mode \
  udp_port_lidar udp_port_imu sensor_info prod_line build_rev prod_sn lidar_intrinsics \
  lidar_to_sensor_transform LEGACY RNG19_RFL8_SIG16_NIR16 RNG19_RFL8_SIG16_NIR16_DUAL \
  RNG15_RFL8_NIR8 512x10 1024x10 2048x10 4096x5; do
  echo "\"\\\"$key\\\"\"" >>"$dictionary"
done

status=0
for fuzzer in "${fuzzers[@]}"; do
  options=(-max_total_time="$seconds" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048
           -artifact_prefix="$build/artifacts/$fuzzer-")
  case "$fuzzer" in
    ouster_packet_fuzzer) options+=(-max_len=60000) ;;
    ouster_metadata_fuzzer) options+=(-max_len=16384 -dict="$dictionary") ;;
  esac
  log="$build/$fuzzer.log"
  echo "== $fuzzer: ${seconds} s (log: $log)"
  if "$build/$fuzzer" "${options[@]}" "$work/$fuzzer/corpus" "$work/$fuzzer/seeds" >"$log" 2>&1; then
    executions="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)"
    rate="$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)"
    coverage="$(grep -o 'cov: [0-9]*' "$log" | tail -1)"
    echo "   ok: ${executions:-?} executions (${rate:-?}/s), ${coverage:-cov: ?}"
  else
    status=1
    echo "   FAILED: see $log; reproducer in $build/artifacts/" >&2
    grep -E "ERROR|SUMMARY|runtime error" "$log" | head -5 >&2 || true
  fi
done
exit "$status"
