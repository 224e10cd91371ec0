#!/usr/bin/env bash
# Installs iproute2 (`ip`) where it is missing, for the two-host transport test
# (tests/daemon_transports.rs: two network namespaces joined by a veth pair; skipped with
# a message without root or `ip`). Needs root (apt-get). Creates no namespace itself.
set -euo pipefail
if command -v ip >/dev/null 2>&1; then
  echo "ip: $(command -v ip)"
  exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: ip missing and cannot be installed here (needs root and apt-get):" \
       "the two-host transport test will be skipped" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq || echo "note: apt-get update failed; trying the install anyway" >&2
apt-get install -y -qq iproute2 >/dev/null \
  || echo "note: apt-get install iproute2 failed: the two-host transport test will be skipped" >&2
command -v ip >/dev/null 2>&1 && echo "ip: $(command -v ip)"
exit 0
