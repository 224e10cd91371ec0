#!/bin/bash
# usage: scripts/bench-tail/quiet.sh NEW_BIN OUT_DIR OLD_BIN   (EXTRA="--rounds 20000" for the long set)
# bench comms --pin same alternated with the 62fcbd7 build, six rounds; then huddle sim 300 s,
# seeds 1-3, five rounds, alternated, CPU time by /usr/bin/time. Summarise: quiet-sum.py OUT_DIR
BIN=$1; OUT=$2; OLD=${3:?usage: quiet.sh NEW_BIN OUT_DIR OLD_BIN (a release build of 62fcbd7)}
mkdir -p $OUT; cd /tmp
for r in 1 2 3 4 5 6; do
  for tag in new old; do
    B=$BIN; [ $tag = old ] && B=$OLD
    echo "$(cut -d' ' -f1 /proc/loadavg)" > $OUT/comms-$r-$tag.load
    $B bench comms --pin same --json $EXTRA > $OUT/comms-$r-$tag.json 2>/dev/null
  done
done
for r in 1 2 3 4 5; do for s in 1 2 3; do for tag in new old; do
  B=$BIN; [ $tag = old ] && B=$OLD
  echo "$(cut -d' ' -f1 /proc/loadavg)" > $OUT/sim-$r-$s-$tag.load
  /usr/bin/time -f '%U %S' -o $OUT/sim-$r-$s-$tag.time $B sim --seed $s --duration 300s --json > $OUT/sim-$r-$s-$tag.json 2>/dev/null
done; done; done
