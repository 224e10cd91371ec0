#!/usr/bin/env bash
# Installs Debian's sox where it is missing, for the audio crate's second room test
# (audio/tests/rooms.rs builds a hall with sox's `reverb`, skipped with a message without
# it). Needs root (apt-get); never fails the caller.
set -euo pipefail
if command -v sox >/dev/null 2>&1; then
  echo "sox: $(command -v sox)"
  exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: sox missing and cannot be installed here (needs root and apt-get):" \
       "the sox room test will be skipped" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq || echo "note: apt-get update failed; trying the install anyway" >&2
apt-get install -y -qq sox >/dev/null \
  || echo "note: apt-get install sox failed: the sox room test will be skipped" >&2
command -v sox >/dev/null 2>&1 && echo "sox: $(command -v sox)"
exit 0
