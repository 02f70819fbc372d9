# What the measuring scripts (soak.sh, net-bench.sh, natnet-flood.sh, control_load.sh)
# share; each sources it.

# facecapd refuses root unless told; these scripts run it only to measure it, and CI
# containers run them as root.
[ "$(id -u)" -ne 0 ] || export FACECAPD_ALLOW_ROOT=1

# The soak's replay: the ICT rig at 240 Hz for 20 s (the built-in motion, 48 markers spread
# over the face as facecapd's default marker set places them, 0.1 mm noise, 0.5% dropouts),
# to be looped. It has no head markers: head stabilisation is off.
# Usage: make_ict_240hz_replay FACECAP_BINARY RIG_DIR OUTPUT.fcrec
make_ict_240hz_replay() {
  "$1" synth --rig "$2" --rate 240 --frames 4800 --markers 48 --noise 0.1 --dropout 0.005 -o "$3" >/dev/null
}

# A command prefix that runs a peer standing in for another machine (a Motive server, a
# device) at SCHED_FIFO 30, below facecapd's threads, so that a loaded host does not make
# its stream bursty; empty where real-time scheduling is not allowed.
# Usage: "${remote_peer_prefix[@]}" facecap natnet-serve ...
remote_peer_prefix=()
if command -v chrt >/dev/null && chrt -f 30 true 2>/dev/null; then remote_peer_prefix=(chrt -f 30); fi

# The control API's port from facecapd's log (started with control.http.port=0), once it
# has solved its first frame; fails, with the log on stderr, when facecapd stops first or
# 30 s pass. Usage: port=$(control_port_when_ready LOG PID)
control_port_when_ready() {
  local log=$1 pid=$2 port=""
  for _ in $(seq 1 300); do
    port=$(sed -n 's|.*control API on http://127\.0\.0\.1:\([0-9]*\).*|\1|p' "$log" | head -1)
    if [ -n "$port" ] && grep -q "ready: first frame solved" "$log"; then
      echo "$port"
      return 0
    fi
    kill -0 "$pid" 2>/dev/null || { cat "$log" >&2; echo "FAILED: facecapd stopped" >&2; return 1; }
    sleep 0.1
  done
  cat "$log" >&2
  echo "FAILED: facecapd did not start its control API within 30 s" >&2
  return 1
}

# A scratch directory in $work, removed at exit together with the facecapd the script
# started in the background (its pid in $pid, empty until then).
# Usage: make_work_dir_with_daemon_cleanup
make_work_dir_with_daemon_cleanup() {
  work=$(mktemp -d)
  pid=""
  trap 'cleanup_work_dir_and_daemon' EXIT
}
cleanup_work_dir_and_daemon() {
  [ -z "$pid" ] || kill "$pid" 2>/dev/null || true
  [ -z "$pid" ] || wait "$pid" 2>/dev/null || true
  rm -rf "$work"
}
