#!/usr/bin/env bash
# Stages `cmake --install` of a build tree with DESTDIR (into BUILD_DIR/staged-install) and
# checks what it gives: facecapd and facecap in the bin dir, the configuration in
# sysconfdir/facecap, the units (facecapd, facecapd@ per actor) with their paths filled in from the install prefix, the
# sysusers.d and tmpfiles.d entries, and the docs the unit's Documentation= points at.
# Then `systemd-analyze verify` must accept each staged unit run from the staged binaries,
# and `systemd-analyze security` must rate each one's exposure at or below 2.0.
# Run by ctest; exits 77 (skipped) where systemd-analyze is not installed.
# Usage: systemd/check-unit.sh BUILD_DIR
set -euo pipefail
build=$(cd "${1:?usage: check-unit.sh BUILD_DIR}" && pwd)
if ! command -v systemd-analyze >/dev/null; then
  echo "SKIPPED: systemd-analyze is not installed (Debian package: systemd)"
  exit 77
fi
stage="$build/staged-install"
rm -rf "$stage"
DESTDIR="$stage" cmake --install "$build" >/dev/null
prefix=$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$build/CMakeCache.txt")
unit_file="$stage$prefix/lib/systemd/system/facecapd.service"

failed=0
expect() {  # expect TEST-ARGS... : a staged file that must be there
  if test "$@"; then echo "ok: ${*: -1}"; else echo "MISSING: ${*: -1}"; failed=1; fi
}
expect -f "$unit_file"
expect -f "$(dirname "$unit_file")/facecapd@.service"
[ "$failed" = 0 ] || exit 1
# The unit's own paths, as configured: ExecStart=BINDIR/facecapd --config SYSCONFDIR/facecap/facecapd.toml
facecapd=$(sed -n 's/^ExecStart=\([^ ]*\) .*/\1/p' "$unit_file")
config=$(sed -n 's/^ExecStart=[^ ]* --config \([^ ]*\).*/\1/p' "$unit_file")
documentation=$(sed -n 's/^Documentation=file:\(.*\)/\1/p' "$unit_file")
case "$facecapd" in "$prefix"/*) ;; *) echo "ExecStart= $facecapd is not under the prefix $prefix"; failed=1 ;; esac
grep -q '@[A-Z_]*@' "$unit_file" && { echo "unfilled @VARIABLE@ in the unit"; failed=1; }
expect -x "$stage$facecapd"
expect -x "$stage$(dirname "$facecapd")/facecap"
expect -f "$stage$config"
expect -f "$stage$documentation"
expect -f "$stage$prefix/lib/sysusers.d/facecap.conf"
expect -f "$stage$prefix/lib/tmpfiles.d/facecap.conf"
[ "$failed" = 0 ] || exit 1

# verify insists that the commands exist: run them from the stage.
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
bindir=$(dirname "$facecapd")
for unit in facecapd.service facecapd@.service; do
  # verify insists that ExecStart= exists: run the staged binaries.
  sed "s|$bindir/|$stage$bindir/|g" "$(dirname "$unit_file")/$unit" > "$work/$unit"
  systemd-analyze verify "$work/$unit"
  echo "$unit: systemd-analyze verify: ok"
  report=$(systemd-analyze security --offline=true "$work/$unit" 2>&1)
  exposure=$(sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p' <<<"$report")
  echo "$unit: systemd-analyze security: exposure $exposure"
  if [ -z "$exposure" ]; then
    echo "$report"
    exit 1
  fi
  awk -v e="$exposure" 'BEGIN { exit !(e <= 2.0) }' || { echo "$report"; echo "$unit: exposure $exposure is above 2.0"; exit 1; }
done
