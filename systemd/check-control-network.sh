#!/usr/bin/env bash
# systemd/facecapd-control-network against configurations in a network namespace whose
# loopback device also holds 10.77.0.5/24 (a stand-in stage network): the drop-in allows
# the subnet of control.http.address, none for loopback (an old one removed), 0.0.0.0
# refused without --subnet, an address no interface holds refused; `systemd-analyze
# verify` accepts the unit with the drop-in. Exits 77 where network namespaces are not allowed.
# Usage: systemd/check-control-network.sh BUILD_DIR   (run by ctest)
set -euo pipefail
build=$(cd "${1:?usage: check-control-network.sh BUILD_DIR}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
if [ -z "${FACECAP_IN_NAMESPACE:-}" ]; then
  unshare -rn true 2>/dev/null || { echo "SKIPPED: cannot create a network namespace (unshare -rn)"; exit 77; }
  exec env FACECAP_IN_NAMESPACE=1 unshare -rn "$0" "$@"
fi
ip link set lo up
ip addr add 10.77.0.5/24 dev lo
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
token="$scratch/token"
echo s3cret > "$token"
chmod 600 "$token"
config() {  # config NAME ADDRESS
  printf '[control.http]\nenabled = true\naddress = "%s"\ntoken_file = "%s"\n' "$2" "$token" > "$scratch/$1.toml"
}
run() { "$here/facecapd-control-network" --facecapd "$build/daemon/facecapd" --dropin-root "$scratch/units" "$@"; }
dropin="$scratch/units/facecapd.service.d/50-control-network.conf"
failed=0
expect() {  # expect WHAT COMMAND...: the command must succeed
  local what=$1; shift
  if "$@"; then echo "ok: $what"; else echo "FAIL: $what"; failed=1; fi
}

config stage 10.77.0.5
run --config "$scratch/stage.toml"
expect "a LAN address allows its interface's subnet" grep -qx 'IPAddressAllow=10.77.0.0/24' "$dropin"
run --config "$scratch/stage.toml" --subnet 10.77.0.0/16 --unit facecapd@anna.service
expect "--subnet and --unit choose the network and the instance" \
  grep -qx 'IPAddressAllow=10.77.0.0/16' "$scratch/units/facecapd@anna.service.d/50-control-network.conf"
if command -v systemd-analyze >/dev/null && [ -f "$build/install-check/prefix/lib/systemd/system/facecapd.service" ]; then
  mkdir -p "$scratch/verify/facecapd.service.d"
  cp "$build/install-check/prefix/lib/systemd/system/facecapd.service" "$scratch/verify/"
  cp "$dropin" "$scratch/verify/facecapd.service.d/"
  expect "systemd-analyze verify accepts the unit with the drop-in" \
    env SYSTEMD_UNIT_PATH="$scratch/verify:" systemd-analyze verify "$scratch/verify/facecapd.service"
fi
config local 127.0.0.1
run --config "$scratch/local.toml"
expect "loopback needs no drop-in: an old one is removed" test ! -e "$dropin"
config any 0.0.0.0
said=$(run --config "$scratch/any.toml" 2>&1) && failed=1
expect "0.0.0.0 without --subnet is refused, saying why" grep -q "name the stage network with --subnet" <<<"$said"
config elsewhere 10.99.0.1
said=$(run --config "$scratch/elsewhere.toml" 2>&1) && failed=1
expect "an address no interface holds is refused, saying so" grep -q "no interface of this machine holds 10.99.0.1" <<<"$said"
[ "$failed" = 0 ]
