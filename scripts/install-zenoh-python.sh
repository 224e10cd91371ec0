#!/usr/bin/env bash
# Installs the official Zenoh Python API (eclipse-zenoh) and pycdr2 from PyPI for the
# bridge's tests: bridge/tests/mirror.rs runs a late joiner written in Python and
# bridge/tests/cdr_reference.rs checks the --ros2 CDR bytes against pycdr2. Both skip with
# a message without them. Never fails the caller.
set -euo pipefail
if ! command -v python3 >/dev/null 2>&1; then
  echo "note: no python3: the bridge's Python checks will be skipped" >&2
  exit 0
fi
python3 -m pip install --quiet --disable-pip-version-check --root-user-action=ignore \
    "eclipse-zenoh==1.10.2" "pycdr2==1.0.0" \
  || echo "note: eclipse-zenoh / pycdr2 could not be installed: the bridge's Python checks will be skipped" >&2
python3 -c "import zenoh, pycdr2; print('zenoh (python)', zenoh.__version__ if hasattr(zenoh, '__version__') else 'ok')" || true
exit 0
