#!/usr/bin/env bash
# Actors per box: N facecapd instances on this machine, each solving the ICT FaceKit rig
# (../shared/data/ict-face) from its own looped replay at RATE Hz, each pinned to a core of
# its own when there are enough (taskset). Reports per instance, from its stats file: frames
# solved, missed deadlines (and how many started late), solve-to-publish latency p99 and
# the CPU it used; and the machine's load average before and after.
# Goal: 0 missed deadlines for every instance.
#
# Usage: scripts/actors-bench.sh [--actors N] [--rate HZ] [--seconds S] [--kernels PATH]
#                                [--set KEY=VALUE ...] [--strict] [--build DIR]
#   --kernels PATH  facecapd's solver.kernels (auto, avx512, avx2, portable)
#   --set KEY=VALUE another facecapd setting for every instance (repeatable)
#   --strict        exit 1 when an instance missed a deadline
# Exits 77 (skipped) when ../shared/data/ict-face is absent.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
. "$here/scripts/bench-lib.sh"
build_dir=${FACECAP_BUILD_DIR:-$here/build}
actors=2 rate=240 seconds=60 kernels=auto strict=0
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --actors) actors=$2; shift ;;
    --rate) rate=$2; shift ;;
    --seconds) seconds=$2; shift ;;
    --kernels) kernels=$2; shift ;;
    --set) extra+=(--set "$2"); shift ;;
    --strict) strict=1 ;;
    --build) build_dir=$2; shift ;;
    *) echo "usage: $0 [--actors N] [--rate HZ] [--seconds S] [--kernels PATH] [--set KEY=VALUE ...] [--strict] [--build DIR]" >&2; exit 2 ;;
  esac
  shift
done

shared=${FACECAP_SHARED_DATA:-$here/../shared/data}
rig="$shared/ict-face"
if [ ! -d "$rig" ]; then
  echo "SKIPPED: $rig is absent (clone ../shared beside the checkout to run the actors benchmark)"
  exit 77
fi
facecap="$build_dir/tools/facecap"
facecapd="$build_dir/daemon/facecapd"
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

make_ict_240hz_replay "$facecap" "$rig" "$work/ict-240.fcrec"
cores=$(nproc)
echo "actors-bench: $actors facecapd on $cores cores, ICT rig at $rate Hz for $seconds s, kernels $kernels${extra[*]:+, ${extra[*]}}; load average $(cut -d' ' -f1-3 /proc/loadavg) before"
for i in $(seq 1 "$actors"); do
  pin=()
  [ "$actors" -le "$cores" ] && pin=(taskset -c $(( i - 1 )))
  "${pin[@]}" "$facecapd" \
    --set "rig.path=$rig" \
    --set source.driver=replay --set "source.replay.file=$work/ict-240.fcrec" --set source.replay.loop=true \
    --set calibration.head_markers=0 \
    --set "loop.rate_hz=$rate" \
    --set "solver.kernels=$kernels" \
    --set "outputs.shm.name=facecap-actors-bench-$$-$i" \
    --set "control.run_seconds=$seconds" \
    --set "logging.stats_interval_s=$seconds" \
    --set "logging.stats_file=$work/stats-$i.json" "${extra[@]}" > "$work/log-$i.txt" 2>&1 &
  pids+=($!)
done
status=0
for p in "${pids[@]}"; do wait "$p" || status=1; done
pids=()
echo "load average $(cut -d' ' -f1-3 /proc/loadavg) after"
[ "$status" -eq 0 ] || { echo "FAILED: a facecapd exited with an error"; tail -5 "$work"/log-*.txt; exit 1; }
python3 - "$strict" "$work"/stats-*.json <<'PY'
import json, sys
strict, files = sys.argv[1] == "1", sys.argv[2:]
missed_any = False
for i, path in enumerate(files, 1):
    s = json.load(open(path))
    lat = s["latency_ms"]
    missed_any |= s["missed_deadlines"] > 0
    print(f"actor {i}: {s['frames_solved']} frames in {s['seconds']:.1f} s ({s['solved_fps']:.1f} fps), "
          f"missed deadlines {s['missed_deadlines']} ({s['late_start_misses']} started late), "
          f"received -> published p50 {lat['p50']:.2f} p99 {lat['p99']:.2f} max {lat['max']:.2f} ms, "
          f"longest tick {s['max_tick_ms']:.2f} ms, CPU {s['cpu_percent']:.0f}%")
print(f"goal 0 missed deadlines for every actor: {'NOT met' if missed_any else 'met'}")
sys.exit(1 if strict and missed_any else 0)
PY
