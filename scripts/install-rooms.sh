#!/usr/bin/env bash
# Installs what the audio crate's image-source room tests need (audio/tests/image_rooms.rs
# runs audio/rooms/make_rooms.py): espeak-ng from Debian, numpy, scipy and pyroomacoustics
# from PyPI. The tests skip with a message without them. Never fails the caller.
set -uo pipefail
if ! command -v espeak-ng >/dev/null 2>&1; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -qq espeak-ng >/dev/null 2>&1 \
      || { apt-get update -qq && apt-get install -y -qq espeak-ng >/dev/null; } \
      || echo "note: apt-get install espeak-ng failed: the image-room tests will be skipped" >&2
  else
    echo "note: espeak-ng missing and cannot be installed here (needs root and apt-get):" \
         "the image-room tests will be skipped" >&2
  fi
fi
if command -v python3 >/dev/null 2>&1; then
  python3 -c "import numpy, scipy, pyroomacoustics" 2>/dev/null \
    || python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
         numpy scipy pyroomacoustics \
    || echo "note: pip install pyroomacoustics failed: the image-room tests will be skipped" >&2
else
  echo "note: no python3: the image-room tests will be skipped" >&2
fi
command -v espeak-ng >/dev/null 2>&1 && echo "espeak-ng: $(command -v espeak-ng)"
python3 -c "import pyroomacoustics as p; print('pyroomacoustics', p.__version__)" 2>/dev/null
exit 0
