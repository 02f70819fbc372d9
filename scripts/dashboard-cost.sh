#!/usr/bin/env bash
# What the operator dashboard costs the solve thread: facecapd on the sim source, its
# control API on, run after run, alternating runs with no browser and runs with BROWSERS
# headless chromium processes on the live view (each drawing the stream at 30 frames a
# second with the mesh), so that what the machine misses anyway is told apart from what the
# dashboard costs. Each run's figures come from facecapd's stats file: missed deadlines,
# the loop's solve and output stages (mean and max), and what the stream output's offer
# costs the solve thread.
#
# Usage: scripts/dashboard-cost.sh [--rounds R] [--seconds S] [--browsers N] [--rate HZ] [--build DIR]
#   default 3 rounds of (S=20 s without browsers, 20 s with 2), the loop at 120 Hz
# Exits 77 (skipped) without chromium or the dashboard's npm packages.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
. "$here/scripts/bench-lib.sh"
build_dir=${FACECAP_BUILD_DIR:-$here/build}
rounds=3
seconds=20
browsers=2
rate=120
while [ $# -gt 0 ]; do
  case "$1" in
    --rounds) rounds=$2; shift ;;
    --seconds) seconds=$2; shift ;;
    --browsers) browsers=$2; shift ;;
    --rate) rate=$2; shift ;;
    --build) build_dir=$2; shift ;;
    *) echo "usage: $0 [--rounds R] [--seconds S] [--browsers N] [--rate HZ] [--build DIR]" >&2; exit 2 ;;
  esac
  shift
done
chromium=${FACECAP_CHROMIUM:-/usr/bin/chromium}
if [ ! -x "$chromium" ] || [ ! -d "$here/dashboard/node_modules/playwright-core" ] || [ ! -f "$build_dir/dashboard/www/index.html" ]; then
  echo "SKIPPED: needs $chromium (Debian package chromium), dashboard/node_modules (npm ci) and the built dashboard"
  exit 77
fi
facecapd="$build_dir/daemon/facecapd"
make_work_dir_with_daemon_cleanup

# One run: facecapd for `seconds` plus the browsers' start-up allowance; with browsers
# attached from the first solved frame on when $1 is "browsers".
run() {
  local phase=$1 n=$2 stats="$work/$1-$2.json"
  "$facecapd" \
    --set source.sim.rate_hz="$rate" --set loop.rate_hz="$rate" \
    --set "outputs.shm.name=facecap-dashcost-$$" \
    --set control.http.enabled=true --set control.http.port=0 \
    --set "control.run_seconds=$(( seconds + 6 ))" \
    --set "logging.stats_file=$stats" \
    > "$work/facecapd.log" 2>&1 &
  pid=$!
  local port
  port=$(control_port_when_ready "$work/facecapd.log" "$pid")
  if [ "$phase" = browsers ]; then
    node "$here/dashboard/tests/attach.mjs" "http://127.0.0.1:$port/" "$seconds" "$browsers" | sed "s/^/  $phase $n: /"
  fi
  wait "$pid"
  pid=""
}

echo "dashboard cost: facecapd on the sim at $rate Hz, $rounds x ($((seconds + 6)) s with no browser, then with $browsers)"
for n in $(seq 1 "$rounds"); do
  run none "$n"
  run browsers "$n"
done

# Each run's figures, then the phases' sums and means.
node - "$work" "$rounds" <<'EOF_NODE'
const fs = require('fs');
const [work, rounds] = [process.argv[2], Number(process.argv[3])];
const rows = [];
for (let n = 1; n <= rounds; ++n) {
  for (const phase of ['none', 'browsers']) {
    const s = JSON.parse(fs.readFileSync(`${work}/${phase}-${n}.json`, 'utf8'));
    const stream = s.outputs.stream ?? {};
    rows.push({
      phase, n, seconds: s.seconds, frames: s.frames_solved, missed: s.missed_deadlines,
      solve_mean_ms: s.stages.solve.mean_ms, solve_max_ms: s.stages.solve.max_ms,
      outputs_mean_ms: s.stages.outputs.mean_ms, stream_offer_p99_us: stream.offer_us?.p99 ?? 0,
      stream_delivered: stream.delivered ?? 0, latency_p99_ms: s.latency_ms.p99,
    });
  }
}
const f = (x, d = 3) => Number(x).toFixed(d);
console.log('| run | phase | frames | missed deadlines | solve mean ms | solve max ms | outputs mean ms | stream offer p99 µs | frames streamed | latency p99 ms |');
console.log('|---|---|---|---|---|---|---|---|---|---|');
for (const r of rows)
  console.log(`| ${r.n} | ${r.phase} | ${r.frames} | ${r.missed} | ${f(r.solve_mean_ms)} | ${f(r.solve_max_ms, 2)} | ${f(r.outputs_mean_ms, 4)} | ${f(r.stream_offer_p99_us, 1)} | ${r.stream_delivered} | ${f(r.latency_p99_ms, 2)} |`);
for (const phase of ['none', 'browsers']) {
  const p = rows.filter((r) => r.phase === phase);
  const mean = (k) => p.reduce((a, r) => a + r[k], 0) / p.length;
  console.log(`${phase}: ${p.reduce((a, r) => a + r.missed, 0)} missed deadlines in ${p.reduce((a, r) => a + r.frames, 0)} frames; ` +
              `solve mean ${f(mean('solve_mean_ms'))} ms, max ${f(Math.max(...p.map((r) => r.solve_max_ms)), 2)} ms; ` +
              `outputs mean ${f(mean('outputs_mean_ms'), 4)} ms; stream offer p99 ${f(mean('stream_offer_p99_us'), 1)} µs`);
}
EOF_NODE
