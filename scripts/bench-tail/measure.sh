#!/bin/sh
# usage: measure.sh [OUT.jsonl] [NEW_BINARY]; then: python3 table.py OUT.jsonl LABEL
# Interleaved: 62fcbd7's kept binary and this branch's release build, 6 rounds of the
# default and of --rounds 20000; this build with --aa (bare tokio against itself).
OUT=${1:-bench-tail.jsonl}
NEW=${2:-target/release/huddle}
: > $OUT
for i in 1 2 3 4 5 6; do for rounds in 5000 20000; do
  for b in /work/wt/wire-old-huddle-62fcbd7 $NEW; do
    aa=""; [ "$b" = "$NEW" ] && aa="--aa"
    load=$(cut -d' ' -f1-3 /proc/loadavg); start=$(date -u +%H:%M:%S)
    r=$(RUST_LOG=warn $b bench comms --pin same --json --port 47310 --rounds $rounds $aa)
    echo "{\"round\":$i,\"rounds\":$rounds,\"build\":\"$(basename $b)\",\"start\":\"$start\",\"load\":\"$load\",\"r\":$r}" >> $OUT
done; done; done
