#!/usr/bin/env bash
# Installs Debian's cmake and pkg-config where they are missing, for the C API's packaging
# test (ffi/tests/examples.rs builds a program from the installed pkg-config files and
# with CMake's find_package(huddle); each part is skipped with a message without its
# tool). Needs root (apt-get); never fails the caller.
set -euo pipefail
missing=()
for tool in cmake pkg-config readelf; do
  command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "cmake, pkg-config, readelf: present"
  exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: ${missing[*]} missing and cannot be installed here (needs root and apt-get):" \
       "the C packaging checks that need them will be skipped" >&2
  exit 0
fi
packages=()
for tool in "${missing[@]}"; do
  case $tool in
    readelf) packages+=(binutils) ;;
    *) packages+=("$tool") ;;
  esac
done
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq || echo "note: apt-get update failed; trying the install anyway" >&2
apt-get install -y -qq "${packages[@]}" >/dev/null \
  || echo "note: apt-get install ${packages[*]} failed: those checks will be skipped" >&2
exit 0
