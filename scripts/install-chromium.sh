#!/usr/bin/env bash
# Installs Debian's chromium where it is missing, for the team monitor's browser test
# (tests/monitor_browser.rs, skipped with a message without it). Needs root (apt-get).
set -euo pipefail
for name in chromium chromium-browser google-chrome; do
  if command -v "$name" >/dev/null 2>&1; then
    echo "chromium: $(command -v "$name")"
    exit 0
  fi
done
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: chromium missing and cannot be installed here (needs root and apt-get):" \
       "the monitor's browser test will be skipped" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq || echo "note: apt-get update failed; trying the install anyway" >&2
apt-get install -y -qq chromium >/dev/null \
  || echo "note: apt-get install chromium failed: the monitor's browser test will be skipped" >&2
command -v chromium >/dev/null 2>&1 && echo "chromium: $(command -v chromium)"
exit 0
