#!/usr/bin/env bash
# The subscriber guide's three examples (docs/subscribers.md), exactly as the guide shows
# them, built against the installed client library (cmake --install --component client,
# pkg-config, #include <facecap/...>) and run against running facecapds:
#   C on shared memory, started before facecapd and following it across a restart;
#   C++ (as C++17) and facecap subscribe on the UDP stream; Python (ctypes) on UDP.
# Usage: tests/client_examples.sh BUILD_DIR SOURCE_DIR
set -euo pipefail

build=$(cd "$1" && pwd)
source_dir=$(cd "$2" && pwd)
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT
fail() { echo "FAILED: $*"; exit 1; }

# Installed as a renderer's build would find it.
cmake --install "$build" --prefix "$work/prefix" --component client >/dev/null
library=$(find "$work/prefix" -name 'libfacecap_client.so.1' | head -1)
[ -n "$library" ] || fail "no libfacecap_client.so.1 installed"
[ -f "$work/prefix/include/facecap/facecap_client.h" ] || fail "no include/facecap/facecap_client.h installed"
libdir=$(dirname "$library")
export PKG_CONFIG_PATH="$libdir/pkgconfig" LD_LIBRARY_PATH="$libdir"
[ "$(readelf -d "$library" | sed -n 's/.*soname: \[\(.*\)\]/\1/p')" = libfacecap_client.so.1 ] || fail "soname"

# Each example: the code block after its marker in the guide.
for example in subscriber.c subscriber.cpp subscriber.py; do
  awk -v marker="<!-- example: $example -->" '
    $0 == marker { found = 1; next }
    found && /^```/ { if (inside) exit; inside = 1; next }
    inside { print }' "$source_dir/docs/subscribers.md" > "$work/$example"
  [ -s "$work/$example" ] || fail "docs/subscribers.md has no $example"
done
flags=$(pkg-config --cflags --libs facecap_client)
# shellcheck disable=SC2086
cc -Wall -Wextra -Werror "$work/subscriber.c" $flags -o "$work/subscriber_c" || fail "the C example does not build"
# shellcheck disable=SC2086
c++ -std=c++17 -Wall -Wextra -Werror "$work/subscriber.cpp" $flags -o "$work/subscriber_cpp" || fail "the C++ example does not build as C++17"

shm="facecap-test-$$-examples"
port=$(( 40000 + $$ % 20000 ))
facecapd() {  # run seconds, log file
  "$build/daemon/facecapd" --set "outputs.shm.name=$shm" --set outputs.udp.enabled=true --set "outputs.udp.port=$port" \
    --set "control.run_seconds=$1" --set logging.stats_interval_s=0 > "$2" 2>&1 &
  pids+=($!)
}

# C on shared memory, started first: it waits for the segment, then follows a restart.
timeout 30 "$work/subscriber_c" shm "$shm" 400 > "$work/c.out" 2> "$work/c.err" &
c_pid=$!
pids+=("$c_pid")
sleep 0.3
facecapd 2.5 "$work/facecapd-1.log"
first=$!
timeout 20 "$work/subscriber_cpp" udp "127.0.0.1:$port" 100 > "$work/cpp.out" || fail "the C++ example: $(tail -3 "$work/cpp.out")"
wait "$first" || fail "facecapd exited with an error: $(tail -5 "$work/facecapd-1.log")"

# Long enough for both subscribers on a loaded machine (a 4 s run ended before `facecap
# subscribe` had its second with the suite running beside it); stopped once they are done.
facecapd 30 "$work/facecapd-2.log"
second=$!
timeout 20 python3 "$work/subscriber.py" udp "127.0.0.1:$port" 100 > "$work/py.out" || fail "the Python example: $(tail -3 "$work/py.out")"
"$build/tools/facecap" subscribe --udp "127.0.0.1:$port" --seconds 1 > "$work/subscribe.out" || fail "facecap subscribe --udp"
wait "$c_pid" || fail "the C example: $(tail -3 "$work/c.out") $(cat "$work/c.err")"
kill "$second" 2>/dev/null || true
wait "$second" || true

count() { grep -c "$1" "$2" || true; }
[ "$(count '^frame ' "$work/c.out")" -eq 400 ] || fail "the C example printed $(count '^frame ' "$work/c.out") frames, not 400"
[ "$(count '^writer: rig builtin, 45 shapes' "$work/c.out")" -eq 2 ] || fail "the C example did not follow the restart: $(grep writer "$work/c.out")"
grep -q "facecapd stopped; waiting" "$work/c.err" || fail "the C example never saw facecapd stop"
[ "$(count '^frame ' "$work/cpp.out")" -eq 100 ] || fail "the C++ example printed $(count '^frame ' "$work/cpp.out") frames"
grep -q '^writer: rig builtin, 45 shapes' "$work/cpp.out" || fail "the C++ example got no schema"
[ "$(count '^frame ' "$work/py.out")" -eq 100 ] || fail "the Python example printed $(count '^frame ' "$work/py.out") frames"
grep -q '^writer: 45 shapes' "$work/py.out" || fail "the Python example got no schema"
grep -q "0 incomplete" "$work/subscribe.out" || fail "facecap subscribe --udp: $(tail -2 "$work/subscribe.out")"
echo "C: 400 frames across a restart; C++ and Python: 100 frames each over UDP; facecap subscribe --udp:"
tail -1 "$work/subscribe.out"
