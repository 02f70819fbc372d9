#!/usr/bin/env bash
# facecapd soak benchmark: the ICT FaceKit rig (../shared/data/ict-face) solved at 240 Hz
# from a replay, for 10 minutes (or 20 s with --ci). Reports missed deadlines, end-to-end
# latency (source frame received -> slot published) p50/p99 and CPU use, against the
# goals: zero missed deadlines, p99 under 3 ms.
#
# Usage: scripts/soak.sh [--ci] [--seconds N] [--strict] [--build DIR]
#   --ci       20 s instead of 600 s (what ctest runs)
#   --strict   exit 1 when a goal is missed (default: report only; exit 1 only when the
#              run itself failed)
# Exits 77 (skipped) when ../shared/data/ict-face is absent.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
. "$here/scripts/bench-lib.sh"
build_dir=${FACECAP_BUILD_DIR:-$here/build}
seconds=600
strict=0
while [ $# -gt 0 ]; do
  case "$1" in
    --ci) seconds=20 ;;
    --seconds) seconds=$2; shift ;;
    --strict) strict=1 ;;
    --build) build_dir=$2; shift ;;
    *) echo "usage: $0 [--ci] [--seconds N] [--strict] [--build DIR]" >&2; exit 2 ;;
  esac
  shift
done

shared=${FACECAP_SHARED_DATA:-$here/../shared/data}
rig="$shared/ict-face"
if [ ! -d "$rig" ]; then
  echo "SKIPPED: $rig is absent (clone ../shared beside the checkout to run the soak)"
  exit 77
fi
facecap="$build_dir/tools/facecap"
facecapd="$build_dir/daemon/facecapd"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

make_ict_240hz_replay "$facecap" "$rig" "$work/ict-240.fcrec"

echo "soak: ICT rig at 240 Hz from a replay for $seconds s"
"$facecapd" \
  --set "rig.path=$rig" \
  --set source.driver=replay --set "source.replay.file=$work/ict-240.fcrec" --set source.replay.loop=true \
  --set calibration.head_markers=0 \
  --set loop.rate_hz=240 \
  --set "outputs.shm.name=facecap-soak-$$" \
  --set "control.run_seconds=$seconds" \
  --set "logging.stats_interval_s=$(( seconds >= 60 ? 60 : 10 ))" \
  --set "logging.stats_file=$work/stats.json" \
  2>&1 | sed 's/^/  facecapd: /'

# The figures facecapd wrote when it stopped (nlohmann::json, one field per line).
stats="$work/stats.json"
[ -s "$stats" ] || { echo "FAILED: facecapd wrote no figures"; exit 1; }
field() { sed -n "s/^ *\"$1\": \([-0-9.e+]*\),\{0,1\}$/\1/p" "$stats" | head -1; }
# The same, rounded to $2 decimals.
num() { awk -v v="$(field "$1")" -v d="$2" 'BEGIN { printf "%.*f", d, v }'; }
frames=$(field frames_solved)
missed=$(field missed_deadlines)
p50=$(field p50)
p99=$(field p99)
echo "frames solved $frames in $(num seconds 1) s ($(num solved_fps 1) fps), ticks skipped $(field skipped_ticks)"
late=$(field late_start_misses)
echo "missed deadlines $missed: $late started late (the solve thread was not running at its deadline), $((missed - late)) ran longer than a period"
echo "worst wake-up after a deadline $(num max_wake_late_ms 2) ms, longest tick $(num max_tick_ms 2) ms"
echo "latency received -> published: p50 $(num p50 2) ms, p99 $(num p99 2) ms, max $(num max 2) ms"
echo "CPU $(num cpu_percent 0)% of one core (whole process)"
# Mean cost per frame of each stage that costs anything ("stages" in the stats file).
awk '/"stages"/ { in_stages = 1 } in_stages && /": \{$/ { gsub(/[" :{]/, ""); stage = $0 }
     in_stages && /"mean_ms"/ { gsub(/[",]/, ""); if ($2 >= 0.001) line = line sprintf("%s %.3f ms, ", stage, $2) }
     END { sub(/, $/, "", line); print "per frame: " line }' "$stats"
[ "${frames:-0}" -gt 0 ] || { echo "FAILED: nothing was solved"; exit 1; }
goals_met=1
if [ "$missed" -eq 0 ]; then echo "goal zero missed deadlines: met"; else echo "goal zero missed deadlines: NOT met"; goals_met=0; fi
if awk -v p="$p99" 'BEGIN { exit !(p < 3.0) }'; then echo "goal p99 under 3 ms: met"; else echo "goal p99 under 3 ms: NOT met"; goals_met=0; fi
[ "$strict" -eq 0 ] || [ "$goals_met" -eq 1 ]
