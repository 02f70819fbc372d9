#!/usr/bin/env bash
# facecap quick start: installs the Debian packages facecap needs, builds, and then
#   run   runs the main job on its built-in default (extra arguments are passed on)
#   test  runs the whole test suite (with CI set, also scripts/sanitize: ASan, UBSan and
#         TSan runs of the parsers', recorder's and hand-offs' tests, and a libFuzzer smoke)
# Usage: scripts/quickstart.sh run|test [args...]
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${FACECAP_BUILD_DIR:-$here/build}
mode=${1:-run}
shift || true

# Debian 12 packages: build tools and the libraries listed in docs/building.md.
packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libsuitesparse-dev libqhull-dev libnanoflann-dev
  libtomlplusplus-dev libtinygltf-dev libassimp-dev nlohmann-json3-dev
  libboost-dev libssl-dev libsystemd-dev libspdlog-dev libfmt-dev libcli11-dev libdtl-dev libpcap-dev
  catch2 libbenchmark-dev
  libusb-1.0-0-dev libhidapi-dev libopencv-dev linux-libc-dev  # the usb, hid and v4l2 drivers
  umockdev libumockdev-dev  # the usb and hid drivers' tests fake their devices
  clang libclang-rt-dev  # scripts/fuzz: libFuzzer with ASan and UBSan
  systemd  # systemd-analyze: the test that checks systemd/facecapd.service
  liblo-tools  # oscdump: the tests decode facecapd's VMC output with liblo
  prometheus wrk  # promtool checks /metrics in the tests; wrk drives scripts/control_load.sh
)

install_packages() {
  local missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "quickstart: installing ${missing[*]}"
  local sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# Node.js and npm: the build makes the operator dashboard with them (dashboard/, npm ci
# from its lock file) and the tests' npm peers need them; a Node.js installed otherwise is
# used as it is.
command -v node >/dev/null || packages+=(nodejs)
command -v npm >/dev/null || packages+=(npm)

build() {
  cmake -S "$here" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$build_dir" --parallel "$(nproc)"
}

case "$mode" in
  run)
    install_packages
    build
    # The product on its built-in default: facecapd solving simulated markers, watched
    # through its shared memory, then stopped (facecap daemon-demo --help).
    exec "$build_dir/tools/facecap" daemon-demo "$@"
    ;;
  test)
    # The tests' npm peers (tests/peers: osc decodes the VMC output, gltf-validator and
    # three check exported glTF), Debian's chromium, which the dashboard's browser test
    # drives headless, and blender, which writes the FBX rig the FBX tests load
    # (tests/make_ict_fbx.py; about 45 s to install on the 2-core CI machine).
    packages+=(chromium blender)
    install_packages
    (cd "$here/tests/peers" && npm ci --no-audit --no-fund --loglevel=error)
    build
    status=0
    (cd "$build_dir" && ctest --output-on-failure --parallel "$(nproc)" --label-exclude realtime "$@") || status=$?
    # The tests labelled realtime judge the solve loop's rate and deadlines, each alone on the
    # machine. A neighbour on a shared machine can steal a few deadlines; a slow loop fails
    # again, so each gets one more run after a failure (both runs are in the output).
    (cd "$build_dir" && ctest --output-on-failure --label-regex realtime --repeat until-pass:2 "$@") || status=$?
    # In CI (CI set, as CI runs this command) also the sanitizer builds of the parsers',
    # recorder's and hand-offs' tests and the libFuzzer smoke (scripts/sanitize).
    if [ -n "${CI:-}" ]; then
      FACECAP_BUILD_DIR=$build_dir "$here/scripts/sanitize" --ci || status=1
    fi
    exit "$status"
    ;;
  *)
    echo "usage: $0 run|test [args...]" >&2
    exit 2
    ;;
esac
