#!/usr/bin/env bash
# Installs a build tree as a user would and checks what it gives:
#  1. `cmake --install BUILD --prefix P` into a scratch prefix: every file it writes is
#     under P (install_manifest.txt), facecapd and facecap in P/bin, the configuration in
#     P/etc/facecap, the units (facecapd, facecapd@ per actor) pointing at P's facecapd,
#     configuration and docs, the sysusers.d and tmpfiles.d entries;
#  2. the same with DESTDIR=D and --prefix /opt/facecap-check: every file under D/opt/...;
#  3. `systemd-analyze verify` accepts each unit installed in P as it is (its ExecStart= is
#     P's facecapd), and `systemd-analyze security` rates its exposure at or below 2.0;
#  4. the installed facecapd starts from P with P's configuration and serves its dashboard
#     (when the build made one), then stops cleanly on SIGTERM.
# Run by ctest after a full build; exits 77 (skipped) where systemd-analyze is not installed.
# Usage: systemd/check-unit.sh BUILD_DIR
set -euo pipefail
build=$(cd "${1:?usage: check-unit.sh BUILD_DIR}" && pwd)
if ! command -v systemd-analyze >/dev/null; then
  echo "SKIPPED: systemd-analyze is not installed (Debian package: systemd)"
  exit 77
fi
scratch="$build/install-check"
rm -rf "$scratch"
mkdir -p "$scratch"
prefix="$scratch/prefix"

failed=0
expect() {  # expect TEST-ARGS... : a file that must be there
  if test "$@"; then echo "ok: ${*: -1}"; else echo "MISSING: ${*: -1}"; failed=1; fi
}
outside() {  # outside ROOT FILE...: the files not under ROOT, one a line
  local root=$1; shift
  for f in "$@"; do case "$f" in "$root"/*) ;; *) echo "$f" ;; esac; done
}

# 1. Into a scratch prefix.
cmake --install "$build" --prefix "$prefix" >/dev/null
mapfile -t installed < "$build/install_manifest.txt"
echo "installed ${#installed[@]} files into $prefix"
stray=$(outside "$prefix" "${installed[@]}")
[ -z "$stray" ] || { echo "written outside the prefix $prefix:"; echo "$stray"; failed=1; }
unit_file="$prefix/lib/systemd/system/facecapd.service"
expect -f "$unit_file"
expect -f "$(dirname "$unit_file")/facecapd@.service"
[ "$failed" = 0 ] || exit 1
# The unit's own paths: ExecStart=P/bin/facecapd --config P/etc/facecap/facecapd.toml
facecapd=$(sed -n 's/^ExecStart=\([^ ]*\) .*/\1/p' "$unit_file")
config=$(sed -n 's/^ExecStart=[^ ]* --config \([^ ]*\).*/\1/p' "$unit_file")
documentation=$(sed -n 's/^Documentation=file:\(.*\)/\1/p' "$unit_file")
[ "$facecapd" = "$prefix/bin/facecapd" ] || { echo "ExecStart= runs $facecapd, not $prefix/bin/facecapd"; failed=1; }
[ "$config" = "$prefix/etc/facecap/facecapd.toml" ] || { echo "ExecStart= reads $config, not $prefix/etc/facecap/facecapd.toml"; failed=1; }
grep -q '@[A-Z_]*@' "$prefix"/lib/systemd/system/*.service && { echo "unfilled @VARIABLE@ in a unit"; failed=1; }
expect -x "$facecapd"
expect -x "$prefix/bin/facecap"
expect -f "$config"
expect -f "$documentation"
expect -f "$prefix/lib/sysusers.d/facecap.conf"
expect -f "$prefix/lib/tmpfiles.d/facecap.conf"
[ "$failed" = 0 ] || exit 1

# 2. Staged with DESTDIR: nothing outside DESTDIR/PREFIX.
DESTDIR="$scratch/destdir" cmake --install "$build" --prefix /opt/facecap-check >/dev/null
mapfile -t staged < <(find "$scratch/destdir" -type f -o -type l)
stray=$(outside "$scratch/destdir/opt/facecap-check" "${staged[@]}")
[ -z "$stray" ] || { echo "staged outside DESTDIR/opt/facecap-check:"; echo "$stray"; exit 1; }
[ "${#staged[@]}" = "${#installed[@]}" ] || { echo "DESTDIR staged ${#staged[@]} files, the prefix install ${#installed[@]}"; exit 1; }
grep -q '^ExecStart=/opt/facecap-check/bin/facecapd ' "$scratch/destdir/opt/facecap-check/lib/systemd/system/facecapd.service" ||
  { echo "the staged unit does not run /opt/facecap-check/bin/facecapd"; exit 1; }
echo "ok: DESTDIR staging keeps all ${#staged[@]} files under DESTDIR/opt/facecap-check"

# 3. The installed units as they are.
for unit in facecapd.service facecapd@.service; do
  systemd-analyze verify "$prefix/lib/systemd/system/$unit"
  echo "$unit: systemd-analyze verify: ok"
  report=$(systemd-analyze security --offline=true "$prefix/lib/systemd/system/$unit" 2>&1)
  exposure=$(sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p' <<<"$report")
  echo "$unit: systemd-analyze security: exposure $exposure"
  if [ -z "$exposure" ]; then
    echo "$report"
    exit 1
  fi
  awk -v e="$exposure" 'BEGIN { exit !(e <= 2.0) }' || { echo "$report"; echo "$unit: exposure $exposure is above 2.0"; exit 1; }
done

# 4. The installed facecapd, from P, with P's configuration, in a scratch working directory.
mkdir -p "$scratch/run"
log="$scratch/run/facecapd.log"
(cd "$scratch/run" && FACECAPD_ALLOW_ROOT=1 exec "$facecapd" --config "$config" --set "outputs.shm.name=facecap-install-check-$$" \
   --set control.http.enabled=true --set control.http.port=0 --set control.run_seconds=60) >"$log" 2>&1 &
pid=$!
trap 'kill "$pid" 2>/dev/null || true' EXIT
port=
for _ in $(seq 600); do
  port=$(sed -n 's|.*control API on http://127\.0\.0\.1:\([0-9]*\).*|\1|p' "$log" | head -n1)
  [ -n "$port" ] && break
  kill -0 "$pid" 2>/dev/null || { cat "$log"; echo "the installed facecapd exited before serving"; exit 1; }
  sleep 0.1
done
[ -n "$port" ] || { cat "$log"; echo "the installed facecapd did not open its control API"; exit 1; }
page=$(python3 -c 'import sys, urllib.request; print(urllib.request.urlopen(sys.argv[1]).read().decode())' "http://127.0.0.1:$port/" 2>&1 || true)
if [ -d "$build/dashboard/www" ]; then
  grep -q '<title>facecap' <<<"$page" || { echo "$page"; cat "$log"; echo "the installed facecapd does not serve its dashboard"; exit 1; }
  expect -f "$prefix/share/facecap/dashboard/index.html"
  echo "ok: the installed facecapd serves the dashboard from $prefix/share/facecap/dashboard"
else
  echo "the build has no dashboard (no Node.js): its page not checked"
fi
kill -TERM "$pid"
status=0
wait "$pid" || status=$?
trap - EXIT
[ "$status" = 0 ] || { cat "$log"; echo "the installed facecapd exited with $status on SIGTERM"; exit 1; }
echo "ok: the installed facecapd ran from $prefix and stopped cleanly"
[ "$failed" = 0 ]
