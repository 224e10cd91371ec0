#!/usr/bin/env bash
# Runs the C and C++ examples (two_robots.c, typed_node.c, team_node.c, two_robots.cpp) and the
# bad-argument test under valgrind (memcheck, full leak check): any invalid access or definite/indirect/possible leak fails the run.
# Not part of CI (slow); run it after changing ffi/: `bash ffi/check-memory.sh`.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v valgrind >/dev/null || { echo "SKIPPED: valgrind is not installed"; exit 0; }
cargo build -p huddle-ffi --quiet
cargo test -p huddle-ffi --test boundary --no-run --quiet 2>/dev/null
target=${CARGO_TARGET_DIR:-target}
lib=$target/debug
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cc -std=c11 -g -I ffi/include ffi/examples/two_robots.c $lib/libhuddle.a -lpthread -ldl -lm -o "$out/two_robots"
cc -std=c11 -g -I ffi/include ffi/examples/typed_node.c $lib/libhuddle.a -lpthread -ldl -lm -o "$out/typed_node"
cc -std=c11 -g -I ffi/include ffi/examples/team_node.c $lib/libhuddle.a -lpthread -ldl -lm -o "$out/team_node"
c++ -std=c++17 -g -I ffi/include ffi/examples/two_robots.cpp -L$lib -lhuddle -Wl,-rpath,"$(cd "$lib" && pwd)" -o "$out/two_robots_cpp"
boundary=$(ls -t $lib/deps/boundary-* | grep -v '\.d$' | head -1)
vg=(valgrind --quiet --suppressions=ffi/valgrind.supp --error-exitcode=99 --leak-check=full --show-leak-kinds=definite,indirect,possible --errors-for-leak-kinds=definite,indirect,possible)
# Ports of their own, on loopback only (239.255.x is organisation-local; interface 127.0.0.1).
port=$((40000 + $$ % 20000))
echo "== two_robots.c";   "${vg[@]}" "$out/two_robots" 239.255.201.1 $port
echo "== typed_node.c";    "${vg[@]}" "$out/typed_node" 239.255.201.3 $((port + 2))
echo "== team_node.c";     "${vg[@]}" "$out/team_node" 239.255.201.4 $((port + 3))
echo "== two_robots.cpp"; "${vg[@]}" "$out/two_robots_cpp" 239.255.201.2 $((port + 1))
echo "== tests/boundary.rs"; "${vg[@]}" "$boundary" --test-threads=1 -q
echo "valgrind: no invalid access, no leak"
