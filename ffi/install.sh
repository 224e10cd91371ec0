#!/bin/sh
# Installs huddle for C and C++ under PREFIX: lib/libhuddle.a and lib/libhuddle.so
# (debug info stripped), include/huddle.h and include/huddle.hpp, the pkg-config files
# lib/pkgconfig/huddle.pc (shared) and huddle-static.pc, and the CMake package
# lib/cmake/huddle (find_package(huddle): huddle::huddle, huddle::huddle_static).
#
#   cargo build --profile ffi -p huddle-ffi && ffi/install.sh /usr/local
#   cc app.c $(pkg-config --cflags --libs huddle-static)
#
# Usage: ffi/install.sh PREFIX [PROFILE]   (PROFILE: the cargo profile built, default
# ffi; the libraries are taken from $CARGO_TARGET_DIR or target/, PROFILE dev: debug;
# HUDDLE_LIB_DIR overrides the directory).
set -eu
prefix=${1:?usage: ffi/install.sh PREFIX [PROFILE]}
profile=${2:-ffi}
here=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$here")
case $profile in dev) dir=debug ;; *) dir=$profile ;; esac
libs=${HUDDLE_LIB_DIR:-${CARGO_TARGET_DIR:-$root/target}/$dir}
if [ ! -f "$libs/libhuddle.a" ] || [ ! -f "$libs/libhuddle.so" ]; then
    echo "install.sh: no libhuddle.a/.so in $libs: run cargo build --profile $profile -p huddle-ffi first" >&2
    exit 1
fi
case $prefix in /*) ;; *) prefix=$(pwd)/$prefix ;; esac
version=$(sed -n 's/^version = "\(.*\)"$/\1/p' "$root/Cargo.toml" | head -n 1)
mkdir -p "$prefix/lib/pkgconfig" "$prefix/lib/cmake/huddle" "$prefix/include"
cp "$libs/libhuddle.a" "$libs/libhuddle.so" "$prefix/lib/"
if command -v strip >/dev/null 2>&1; then
    # Debug info is most of a Rust static library (the standard library's included).
    strip --strip-debug "$prefix/lib/libhuddle.a" "$prefix/lib/libhuddle.so"
else
    echo "install.sh: no strip: the libraries keep their debug info" >&2
fi
cp "$here/include/huddle.h" "$here/include/huddle.hpp" "$prefix/include/"
fill() {
    sed -e "s|@PREFIX@|$prefix|g" -e "s|@VERSION@|$version|g" "$here/pkg/$1.in" > "$2/$1"
}
fill huddle.pc "$prefix/lib/pkgconfig"
fill huddle-static.pc "$prefix/lib/pkgconfig"
fill huddleConfig.cmake "$prefix/lib/cmake/huddle"
fill huddleConfigVersion.cmake "$prefix/lib/cmake/huddle"
echo "installed huddle $version in $prefix ($(du -k "$prefix/lib/libhuddle.a" | cut -f1) KiB libhuddle.a)"
