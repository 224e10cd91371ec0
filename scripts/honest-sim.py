#!/usr/bin/env python3
"""The honest-simulator table (#29): every report seed, each preset, both worlds.

    scripts/honest-sim.py [--bin target/release/huddle] [--out /tmp/honest-sim] \
        [--jobs 1] [--duration 300s] [--seeds 501-524] [--table docs/results/honest-sim.md]

Runs (skipping a run whose JSON is already in --out):
  huddle sim --preset P --seed S --duration D --world W --json
for P in competition, competition-ps, wlan, and, under the SPL budget on competition,
--budget spl --policy voi and --policy baseline; W in ideal and drawn. Then writes the
table: per run team / reference for every reference (centralized, told every kick,
delivery, delayed), the delivery ratio, one goer, the conflict against its bound, the
shared-time error; per preset and world the medians and worst; and, under SPL, the blind
robots' error and one goer of VOI against the baseline. Report seeds (this round
501-524) are run once for the note and never used to choose a parameter (docs/seeds.md).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

PRESETS = [
    ("competition", []),
    ("competition-ps", []),
    ("wlan", []),
    ("spl-voi", ["--budget", "spl", "--policy", "voi"]),
    ("spl-baseline", ["--budget", "spl", "--policy", "baseline"]),
]
WORLDS = ["ideal", "drawn"]
# team / reference: reference RMSE over the team's (≥ 1 means the reference is better).
REFS = [
    ("central", "rmse_ratio"),
    ("cK", "rmse_ratio_kicks"),
    ("delivery", "delivery_ratio"),
    ("delayed", "delayed_centralized_ratio"),
]


def seeds_of(spec):
    out = []
    for part in spec.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def run(args, name, extra, world, seed):
    path = os.path.join(args.out, f"{name}-{world}-{seed}.json")
    if os.path.exists(path):
        return path
    preset = "competition" if name.startswith("spl") else name
    cmd = [args.bin, "sim", "--preset", preset, "--seed", str(seed), "--duration",
           args.duration, "--world", world, "--json"] + extra
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        print(f"failed: {' '.join(cmd)}\n{out.stderr}", file=sys.stderr)
        return None
    with open(path + ".tmp", "w") as f:
        f.write(out.stdout)
    os.replace(path + ".tmp", path)
    print(f"done {name} {world} {seed}", file=sys.stderr)
    return path


def load(args, name, world, seed):
    path = os.path.join(args.out, f"{name}-{world}-{seed}.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def med(xs):
    return statistics.median(xs) if xs else float("nan")


def team_over(r, key):
    """team / reference, the target's way round: ≥ 0.98 means not beaten beyond noise."""
    v = r.get(key)
    return 1.0 / v if v else float("nan")


def table(args, seeds):
    lines = ["# The honest simulator: report seeds, ideal and drawn worlds (#29)", ""]
    lines.append(
        f"`scripts/honest-sim.py --seeds {args.seeds} --duration {args.duration}` "
        "(each run `huddle sim --preset P --seed S --duration D --world W --json`; SPL: "
        "competition with `--budget spl`). Report seeds, run once (docs/seeds.md). "
        "Ratios are the report's: team RMSE / reference RMSE at the same instants "
        "(`rmse_ratio`, `rmse_ratio_kicks`, `delivery_ratio`, "
        "`delayed_centralized_ratio`). The target is every one ≥ 0.98: a ratio below "
        "0.98 is a reference the team beat by more than noise (marked **bold**).")
    lines.append("")
    summary = ["## Summary per preset and world", "",
               "| preset | world | runs | central med / min | cK med / min | delivery med / min / max | "
               "delayed med / min | one goer med / min % | conflict > bound | clock err rms med µs | "
               "pose err med m |",
               "|---|---|---|---|---|---|---|---|---|---|---|"]
    per_run = ["## Every run", "",
               "| preset | world | seed | ×central | ×cK | ×delivery | ×delayed | team ball m | "
               "one goer % | conflict / bound ms | clock err rms µs | sim× |",
               "|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def fmt(x, bold_below=None):
        if x is None or x != x:
            return "–"
        s = f"{x:.3f}"
        return f"**{s}**" if bold_below is not None and x < bold_below else s

    for name, _ in PRESETS:
        for world in WORLDS:
            rs = [(s, load(args, name, world, s)) for s in seeds]
            rs = [(s, r) for s, r in rs if r]
            if not rs:
                continue
            col = {k: [r[key] for _, r in rs] for k, key in REFS}
            goer = [r["exactly_one_goer_pct"] for _, r in rs]
            over = sum(1 for _, r in rs if r["longest_conflict_ms"] > r["conflict_bound_ms"])
            clk = [r.get("clock_offset_error_rms_us", float("nan")) for _, r in rs]
            pose = [r.get("pose_rmse_m", float("nan")) for _, r in rs]
            summary.append(
                f"| {name} | {world} | {len(rs)} | {fmt(med(col['central']))} / "
                f"{fmt(min(col['central']), 0.98)} | {fmt(med(col['cK']))} / "
                f"{fmt(min(col['cK']), 0.98)} | {fmt(med(col['delivery']))} / "
                f"{fmt(min(col['delivery']), 0.98)} / {fmt(max(col['delivery']))} | "
                f"{fmt(med(col['delayed']))} / {fmt(min(col['delayed']), 0.98)} | "
                f"{med(goer):.2f} / {min(goer):.2f} | {over}/{len(rs)} | {med(clk):.0f} | "
                f"{med(pose):.3f} |")
            for s, r in rs:
                per_run.append(
                    f"| {name} | {world} | {s} | {fmt(r['rmse_ratio'], 0.98)} | "
                    f"{fmt(r['rmse_ratio_kicks'], 0.98)} | {fmt(r['delivery_ratio'], 0.98)} | "
                    f"{fmt(r['delayed_centralized_ratio'], 0.98)} | {r['team_ball_rmse_m']:.4f} | "
                    f"{r['exactly_one_goer_pct']:.2f} | {r['longest_conflict_ms']:.0f} / "
                    f"{r['conflict_bound_ms']:.0f} | "
                    f"{r.get('clock_offset_error_rms_us', float('nan')):.0f} | "
                    f"{r.get('sim_speed_x', 0):.0f} |")
    spl = ["## Under the SPL budget: VOI against the baseline", "",
           "| world | seed | blind RMSE VOI / baseline m | ratio | one goer VOI / baseline % |",
           "|---|---|---|---|---|"]
    for world in WORLDS:
        ratios, dgoer = [], []
        for s in seeds:
            v, b = load(args, "spl-voi", world, s), load(args, "spl-baseline", world, s)
            if not (v and b):
                continue
            bv, bb = v["blind_team_ball_rmse_m"], b["blind_team_ball_rmse_m"]
            ratio = bv / bb if bb else float("nan")
            ratios.append(ratio)
            dgoer.append(v["exactly_one_goer_pct"] - b["exactly_one_goer_pct"])
            spl.append(f"| {world} | {s} | {bv:.3f} / {bb:.3f} | {ratio:.2f} | "
                       f"{v['exactly_one_goer_pct']:.2f} / {b['exactly_one_goer_pct']:.2f} |")
        if ratios:
            se = statistics.stdev(dgoer) / len(dgoer) ** 0.5 if len(dgoer) > 1 else float("nan")
            spl.append(f"| {world} | mean of {len(ratios)} | | {statistics.mean(ratios):.2f} "
                       f"(≤ 0.8 on {sum(r <= 0.8 for r in ratios)}) | VOI − baseline "
                       f"{statistics.mean(dgoer):+.2f} ± {se:.2f} (se) |")
    return "\n".join(lines + summary + [""] + spl + [""] + per_run) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/huddle")
    ap.add_argument("--out", default="/tmp/honest-sim")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--duration", default="300s")
    ap.add_argument("--seeds", default="501-524")
    ap.add_argument("--table", default="docs/results/honest-sim.md")
    ap.add_argument("--no-run", action="store_true", help="only write the table")
    ap.add_argument("--presets", default=",".join(n for n, _ in PRESETS),
                    help="run only these (the table shows every run found in --out)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    seeds = seeds_of(args.seeds)
    if not args.no_run:
        wanted = args.presets.split(",")
        jobs = [(n, e, w, s) for s in seeds for w in WORLDS for n, e in PRESETS if n in wanted]
        with ThreadPoolExecutor(args.jobs) as ex:
            list(ex.map(lambda j: run(args, *j), jobs))
    with open(args.table, "w") as f:
        f.write(table(args, seeds))
    print(f"wrote {args.table}", file=sys.stderr)


if __name__ == "__main__":
    main()
