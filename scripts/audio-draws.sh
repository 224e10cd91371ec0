#!/bin/sh
# Extra talker draws of 0 dB rows: row seed = S*1000 + row (row numbers of `huddle audio rooms`).
# usage: OUT=DIR SCENE_DIAG=PATH scripts/audio-draws.sh S "ROOM LONG_SHARE ROW" ...
# (scene_diag: cargo build --release -p audio --examples; the room set: audio/rooms/make_rooms.py --seed 2)
S=$1; shift
D=/tmp/roomsets/seed2
X=${SCENE_DIAG:-target/release/examples/scene_diag}
for spec in "$@"; do
  set -- $spec
  # Rows may be written as `huddle audio rooms` prints them (009): sh reads 009 as octal.
  room=$1; long=$2; row=$(echo "$3" | sed 's/^0*//')
  seed=$((S*1000+row))
  $X $D $room 0 4 $long 1000 $seed one checked > ${OUT:-/tmp}/draw-$seed-$room.txt 2>&1
  echo "seed $seed $(head -1 ${OUT:-/tmp}/draw-$seed-$room.txt)"
  grep ^cause ${OUT:-/tmp}/draw-$seed-$room.txt
done
