#!/usr/bin/env bash
# NatNet robustness under a flood: `facecap natnet-serve` streams a real AnimFace take
# (../shared/data/markers) at 240 Hz and sends 10,000 bad datagrams a second to the same
# data port (random bytes, packets cut short or longer than their headers say, frames with
# impossible counts), while facecapd solves the stream at 240 Hz for 10 s (--ci: 3 s).
# Reports the frames solved, the bad datagrams sent and counted, and the missed deadlines.
#
# Usage: scripts/natnet-flood.sh [--ci] [--seconds N] [--rate N] [--multicast] [--build DIR]
#   --ci         3 s instead of 10 s (what ctest runs), judged at half the stream's rate: the
#                rate is a benchmark on a quiet machine (natnet-serve sends the stream and the
#                flood from one process, whose frames bunch on a busy 2-core machine and are
#                replaced by newer ones before a tick: 166-215 fps in four runs); the
#                CI run shows that the flood stalls nothing
#   --rate N     bad datagrams a second (default 10000)
#   --multicast  stream to 239.255.42.99 on the loopback interface (default: unicast to the
#                data port, which works where loopback multicast does not)
# Exits 1 when facecapd crashes or fails, counts no bad datagram, or solves under 90% (--ci:
# 50%) of the stream's 240 frames a second (also when natnet-serve itself fell behind: the run did
# not show the stream solved at its rate); 77 (skipped) without ../shared/data.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
. "$here/scripts/bench-lib.sh"
build_dir=${FACECAP_BUILD_DIR:-$here/build}
seconds=10
rate=10000
least_share=0.9  # of the stream's 240 frames a second
mode=unicast-data-port
while [ $# -gt 0 ]; do
  case "$1" in
    --ci) seconds=3 least_share=0.5 ;;
    --seconds) seconds=$2; shift ;;
    --rate) rate=$2; shift ;;
    --multicast) mode=multicast ;;
    --build) build_dir=$2; shift ;;
    *) echo "usage: $0 [--ci] [--seconds N] [--rate N] [--multicast] [--build DIR]" >&2; exit 2 ;;
  esac
  shift
done

shared=${FACECAP_SHARED_DATA:-$here/../shared/data}
take="$shared/markers/animface/JawMoCap.trc"
if [ ! -f "$take" ]; then
  echo "SKIPPED: $take is absent (clone ../shared beside the checkout to run the flood)"
  exit 77
fi
facecap="$build_dir/tools/facecap"
facecapd="$build_dir/daemon/facecapd"
work=$(mktemp -d)
serve_pid=
cleanup() {
  [ -z "$serve_pid" ] || kill "$serve_pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
port=$(( 40000 + $$ % 10000 * 2 % 10000 ))

"$facecap" calibrate --rig builtin --take "$take" -o "$work/actor.toml" >/dev/null
"${remote_peer_prefix[@]}" "$facecap" natnet-serve "$take" --loop --rate 240 --mode "$mode" --address 127.0.0.1 --interface 127.0.0.1 \
  --command-port "$port" --data-port $((port + 1)) --marker-set Face --seconds $((seconds + 10)) \
  --garbage-rate "$rate" >"$work/serve.log" 2>&1 &
serve_pid=$!
for _ in $(seq 100); do grep -q "commands on" "$work/serve.log" && break; sleep 0.05; done

echo "flood: $rate bad datagrams a second at the data port for $seconds s while facecapd solves a 240 Hz NatNet stream ($mode)"
status=0
"$facecapd" \
  --set source.driver=natnet --set source.natnet.server_address=127.0.0.1 --set source.natnet.local_interface=127.0.0.1 \
  --set "source.natnet.command_port=$port" --set "source.natnet.data_port=$((port + 1))" \
  --set source.natnet.marker_set=Face \
  --set "calibration.file=$work/actor.toml" \
  --set loop.rate_hz=240 \
  --set "outputs.shm.name=facecap-flood-$$" \
  --set "control.run_seconds=$seconds" \
  --set logging.stats_interval_s=0 \
  --set "logging.stats_file=$work/stats.json" \
  >"$work/facecapd.log" 2>&1 || status=$?
kill -INT "$serve_pid" 2>/dev/null || true
wait "$serve_pid" 2>/dev/null || true
serve_pid=
sed 's/^/  facecapd: /' "$work/facecapd.log" | grep -v "natnet: dropped" || true
echo "  natnet-serve: $(tail -1 "$work/serve.log" | sed 's/^natnet-serve: //')"
if [ "$status" -ne 0 ]; then echo "FAILED: facecapd exited with status $status"; exit 1; fi

stats="$work/stats.json"
[ -s "$stats" ] || { echo "FAILED: facecapd wrote no figures"; exit 1; }
field() { sed -n "s/^ *\"$1\": \([-0-9.e+]*\),\{0,1\}$/\1/p" "$stats" | head -1; }
num() { awk -v v="$(field "$1")" -v d="$2" 'BEGIN { printf "%.*f", d, v }'; }
frames=$(field frames_solved)
errors=$(awk '/"source": \{/ { in_source = 1 } in_source && /"errors"/ { gsub(/[^0-9]/, ""); print; exit }' "$stats")
missed=$(field missed_deadlines)
sent=$(sed -n 's/.* \([0-9]*\) bad datagrams sent$/\1/p' "$work/serve.log")
overwritten=$(awk '/"source": \{/ { in_source = 1 } in_source && /"overwritten"/ { gsub(/[^0-9]/, ""); print; exit }' "$stats")
echo "frames solved $frames in $(num seconds 1) s ($(num solved_fps 1) fps of the stream's 240), $overwritten replaced" \
     "by a newer one before a tick took them, $(field idle_ticks) idle ticks; ticks waited up to" \
     "$(num max_jitter_margin_ms 2) ms more for late frames"
echo "bad datagrams sent ${sent:-?}, counted and dropped by facecapd $errors (the rest: before facecapd listened or after it stopped, or lost by the kernel)"
echo "missed deadlines $missed ($(field late_start_misses) started late), worst wake-up $(num max_wake_late_ms 2) ms, latency received -> published p99 $(num p99 2) ms"
echo "CPU $(num cpu_percent 0)% of one core (facecapd)"
[ "${errors:-0}" -gt 0 ] || { echo "FAILED: no bad datagram was counted"; exit 1; }
skipped=$(sed -n 's/.* \([0-9]*\) frame times skipped.*/\1/p' "$work/serve.log")
# The verdict is the solved frame rate against the stream's 240 Hz, whatever the cause of a
# shortfall: a flood the sender cannot send alongside the stream fails too (it says so).
percent=$(awk -v s="$least_share" 'BEGIN { printf "%.0f", 100 * s }')
if awk -v fps="$(field solved_fps)" -v s="$least_share" 'BEGIN { exit !(fps >= s * 240) }'; then
  echo "ok: no crash, the bad datagrams that arrived counted and dropped, the stream solved at $(num solved_fps 1) fps" \
       "(at least $percent% of 240)"
else
  echo "FAILED: $(num solved_fps 1) fps solved, under $percent% of the stream's 240"
  if [ "${skipped:-0}" -gt $((240 * seconds / 100)) ]; then
    echo "  natnet-serve itself skipped $skipped frame times: this machine cannot send $rate bad datagrams a second" \
         "alongside the stream, so the flood, not only facecapd, cut the rate"
  fi
  exit 1
fi
