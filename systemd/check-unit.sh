#!/usr/bin/env bash
# Checks systemd/facecapd.service and the per-actor template facecapd@.service with
# systemd-analyze: `verify` must accept each and `security` must rate its exposure at or
# below 2.0. Run by ctest; exits 77 (skipped)
# where systemd-analyze is not installed.
# Usage: systemd/check-unit.sh FACECAPD_BINARY
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
facecapd=${1:?usage: check-unit.sh FACECAPD_BINARY}
if ! command -v systemd-analyze >/dev/null; then
  echo "SKIPPED: systemd-analyze is not installed (Debian package: systemd)"
  exit 77
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for unit in facecapd.service facecapd@.service; do
  # verify insists that ExecStart= exists: point it at the binary under test.
  sed "s|/usr/bin/facecapd|$facecapd|g" "$here/$unit" > "$work/$unit"
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
