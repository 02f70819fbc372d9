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
