#!/usr/bin/env bash
# `huddle sim --daemons` against the in-process match, per world, seed and run (#27).
#   scripts/daemons-seeds.sh [HUDDLE_BIN] [RUNS] SEED...
#   WORLDS="drawn ideal" picks the worlds (default: both; drawn is the CLI's default).
# Every run keeps its trace (HUDDLE_DAEMONS_TRACE=1) in $OUT/trace-W-S-R.txt and its report
# in $OUT/report-W-S-R.json (OUT default /tmp/daemons-seeds); a row per run on stdout,
# with the load average before the run (`uptime`'s first figure), the in-process run, its
# spread (the same match in process with the link latency moved by 0.5-2 ms: how far the
# seed swings by chance) and the ratio to the spread's median. For a run above 1.3x,
# scripts/daemons-trace.py $OUT/trace-W-S-R.txt says where its squared error comes from.
set -euo pipefail
bin=${1:-target/release/huddle}; shift
runs=${1:-3}; shift
out=${OUT:-/tmp/daemons-seeds}
mkdir -p "$out"
echo "world | seed | run | daemons RMSE m | in process m | ratio | in-process spread m (min-max) | median | ratio to median | pose m daemons / in process | one goer % daemons / in process | stale views | view lag ms p50/p95/max | world behind ms p95/max | load"
for w in ${WORLDS:-drawn ideal}; do
  for s in "$@"; do
    for r in $(seq 1 "$runs"); do
      load=$(cut -d' ' -f1 /proc/loadavg)
      HUDDLE_DAEMONS_TRACE=1 RUST_LOG=warn "$bin" sim --seed "$s" --duration 60s --daemons \
        --world "$w" --json > "$out/report-$w-$s-$r.json" 2> "$out/trace-$w-$s-$r.txt"
      python3 - "$out/report-$w-$s-$r.json" "$w" "$s" "$r" "$load" <<'PY'
import json, sys
p, w, s, r, load = sys.argv[1:]
d = json.load(open(p)); i = d["in_process"]; l = d["view_lag_ms"]; b = d["behind_ms"]
sp = [x["team_ball_rmse_m"] for x in i["spread"]]
print(f"{w} | {s} | {r} | {d['team_ball_rmse_m']:.4f} | {i['team_ball_rmse_m']:.4f} | "
      f"{i['rmse_vs_in_process']:.3f} | {min(sp):.4f}-{max(sp):.4f} | {i['team_ball_rmse_median_m']:.4f} | "
      f"{i['rmse_vs_in_process_median']:.3f} | {d['pose_rmse_m']:.4f} / {i['pose_rmse_m']:.4f} | "
      f"{d['exactly_one_goer_pct']:.2f} / {i['exactly_one_goer_pct']:.2f} | "
      f"{d['stale_views']} | {l['p50']:.2f}/{l['p95']:.2f}/{l['max']:.1f} | {b['p95']:.1f}/{b['max']:.1f} | {load}")
PY
    done
  done
done
