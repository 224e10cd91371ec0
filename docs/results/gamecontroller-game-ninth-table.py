#!/usr/bin/env python3
"""Ninth session (#34): run `huddle sim --budget spl --game MODE` on tuning seeds, both worlds, with env
knobs; summarise. usage: gamecontroller-game-ninth-table.py BIN OUTDIR TAG [--mode restarts|full] [--seeds 4-11] [--env K=V,...] [--jobs 2]"""
import argparse, json, os, subprocess, sys, math
from concurrent.futures import ThreadPoolExecutor
ap = argparse.ArgumentParser()
ap.add_argument("bin"); ap.add_argument("out"); ap.add_argument("tag")
ap.add_argument("--mode", default="restarts"); ap.add_argument("--seeds", default="4-11")
ap.add_argument("--worlds", default="drawn,ideal")
ap.add_argument("--env", default=""); ap.add_argument("--jobs", type=int, default=2)
ap.add_argument("--no-run", action="store_true")
a = ap.parse_args()
lo, hi = map(int, a.seeds.split("-")); seeds = list(range(lo, hi + 1))
worlds = a.worlds.split(",")
env = dict(os.environ)
for kv in filter(None, a.env.split(",")):
    k, v = kv.split("="); env[k] = v
os.makedirs(a.out, exist_ok=True)
def path(w, s): return os.path.join(a.out, f"{a.tag}-{a.mode}-{w}-{s}.json")
def run(job):
    w, s = job
    p = path(w, s)
    if os.path.exists(p) and os.path.getsize(p) > 0: return
    cmd = [a.bin, "sim", "--budget", "spl", "--game", a.mode, "--seed", str(s), "--json"]
    if w != "drawn": cmd += ["--world", w]
    o = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if o.returncode: sys.stderr.write(o.stderr[-2000:]); return
    open(p + ".tmp", "w").write(o.stdout); os.replace(p + ".tmp", p)
if not a.no_run:
    with ThreadPoolExecutor(a.jobs) as ex: list(ex.map(run, [(w, s) for w in worlds for s in seeds]))
budget = 1200 if a.mode == "full" else 600
print(f"{a.tag} ({a.env or 'no knobs'}), --game {a.mode}, seeds {a.seeds}")
print("world | one goer % | blind m (mean) | blind 10-30 s m (pooled) | 0-10 s | 30+ s | budget % | illegal | outside play | kick-offs")
for w in worlds:
    rs = []
    for s in seeds:
        try: rs.append(json.load(open(path(w, s))))
        except Exception: pass
    if not rs: continue
    n = len(rs)
    def pooled(idx):
        ns = sum(r["game_since_kick_off"][i]["blind_samples"] for r in rs for i in idx)
        sq = sum(r["game_since_kick_off"][i]["blind_samples"] * r["game_since_kick_off"][i]["blind_rmse_m"] ** 2 for r in rs for i in idx)
        return math.sqrt(sq / ns) if ns else float("nan")
    print(" | ".join(str(x) for x in [w + f" (n={n})",
        round(sum(r["exactly_one_goer_pct"] for r in rs) / n, 2),
        round(sum(r["blind_team_ball_rmse_m"] for r in rs) / n, 3),
        round(pooled([1]), 3), round(pooled([0]), 3), round(pooled([2, 3, 4]), 3),
        round(sum(100.0 * r["game_messages_counted"] / budget for r in rs) / n, 2),
        sum(r["game_illegal_messages"] for r in rs),
        round(sum(r["game_messages_outside_play"] for r in rs) / n, 1),
        round(sum(r["game_kick_offs"] for r in rs) / n, 1)]))
