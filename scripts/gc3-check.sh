#!/usr/bin/env bash
# The independent check against the league's own GameController (#34): GameController3's
# runtime, headless, referees a shortened game of three `huddle daemon`s, and its count
# of the team's messages is compared with what the daemons say they sent
# (scripts/gc3-check/src/main.rs says what is checked). Exit 0: every check passed;
# 1: a check failed; 2: it could not run (the reason is printed).
#
# usage: scripts/gc3-check.sh GC3 [ROBOTS]
#   GC3_WHISTLE=off: the robot programs hear no whistle (default on: they write
#        local.var.robot.whistle at each kick-off and goal the operator whistles).
#   GC3: a checkout of github.com/RoboCup-SPL/GameController3, or its git directory
#        (no registry has it, so it is not fetched here).
# Needs: root (a network namespace with a veth pair: the GC's broadcasts and the team's
# never leave it), iproute2, and libclang for GC3's bindgen (apt: libclang1-14
# libclang-common-14-dev).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
src="${1:-${GC3_SRC:-}}"
robots="${2:-3}"
if [ -z "$src" ] || [ ! -e "$src" ]; then
  echo "gc3-check: cannot run: give GameController3's source (a checkout or git dir)" >&2
  exit 2
fi
if [ "$(id -u)" != 0 ] || ! command -v ip >/dev/null || ! command -v unshare >/dev/null; then
  echo "gc3-check: cannot run: needs root, ip (iproute2) and unshare for its namespace" >&2
  exit 2
fi
dst="$here/gc3-check/gc3"
if [ -d "$src/objects" ] && [ -f "$src/HEAD" ]; then
  rev="$(git --git-dir="$src" rev-parse HEAD)"
else
  rev="$(git -C "$src" rev-parse HEAD 2>/dev/null || echo unknown)"
fi
# Extracted again only for another revision (a fresh copy would rebuild GC3's crates).
if [ "$rev" = unknown ] || [ "$(cat "$dst/.rev" 2>/dev/null)" != "$rev" ]; then
  rm -rf "$dst"
  mkdir -p "$dst"
  if [ -d "$src/objects" ] && [ -f "$src/HEAD" ]; then
    git --git-dir="$src" archive HEAD | tar -x -C "$dst"
  else
    (cd "$src" && tar -c --exclude=./frontend --exclude=./target .) | tar -x -C "$dst"
  fi
  echo "$rev" > "$dst/.rev"
fi
echo "gc3-check: GameController3 at $rev"
export CARGO_INCREMENTAL=0
huddle="${HUDDLE_BIN:-}"
if [ -z "$huddle" ]; then
  (cd "$repo" && cargo build --release --locked --bin huddle)
  huddle="${CARGO_TARGET_DIR:-$repo/target}/release/huddle"
fi
CARGO_TARGET_DIR="${GC3_CHECK_TARGET:-$here/gc3-check/target}" \
  cargo build --release --manifest-path "$here/gc3-check/Cargo.toml"
bin="${GC3_CHECK_TARGET:-$here/gc3-check/target}/release/gc3-check"
work="$(mktemp -d /tmp/gc3-check.XXXXXX)"
echo "gc3-check: work directory $work"
# A fresh network namespace: loopback, and a veth pair whose one end carries 10.0.0.1/16
# (the SPL field's addressing), so broadcasts to 10.0.255.255 reach every local socket.
set +e
unshare -n bash -c '
  set -e
  ip link set lo up
  ip link add gc0 type veth peer name gc1
  ip addr add 10.0.0.1/16 brd 10.0.255.255 dev gc0
  ip link set gc0 up
  ip link set gc1 up
  exec "$@"' _ "$bin" --gc3 "$dst" --huddle "$huddle" --work "$work" --robots "$robots" --whistle "${GC3_WHISTLE:-on}"
rc=$?
set -e
echo "gc3-check: exit $rc (logs in $work)"
exit $rc
