#!/usr/bin/env python3
"""Where a `huddle sim --daemons` run's team-ball error comes from (#27).

    HUDDLE_DAEMONS_TRACE=1 huddle sim --daemons ... 2> trace.txt
    scripts/daemons-trace.py trace.txt [TOP]

Prints the run's RMSE from the trace, then the TOP (default 5) one-second windows by their
share of the squared error, each with its samples, worst error, ball speed, how many of
the samples the robot saw the ball itself, how far the world ran behind the wall clock,
and whether a goal fell in it.
"""
import re
import sys
from collections import defaultdict

path = sys.argv[1]
top = int(sys.argv[2]) if len(sys.argv) > 2 else 5
sample = re.compile(
    r"trace t=([\d.]+) robot=(\d+) err=([\d.]+) speed=([\d.]+) .* sees=(\w+)(?: behind_ms=([\d.]+))?"
)
goal = re.compile(r"goal t=([\d.]+)")
windows = defaultdict(lambda: {"sq": 0.0, "n": 0, "max": 0.0, "speed": 0.0, "seen": 0, "behind": 0.0})
goals = set()
total_sq, total_n = 0.0, 0
for line in open(path):
    m = sample.match(line)
    if m:
        t, _robot, err, speed, sees, behind = m.groups()
        err, speed = float(err), float(speed)
        w = windows[int(float(t))]
        w["sq"] += err * err
        w["n"] += 1
        w["max"] = max(w["max"], err)
        w["speed"] = max(w["speed"], speed)
        w["seen"] += sees == "true"
        w["behind"] = max(w["behind"], float(behind or 0))
        total_sq += err * err
        total_n += 1
        continue
    m = goal.match(line)
    if m:
        goals.add(int(float(m.group(1))))
if total_n == 0:
    sys.exit(f"{path}: no trace samples (was HUDDLE_DAEMONS_TRACE=1 set?)")
print(f"{path}: {total_n} samples, RMSE {(total_sq / total_n) ** 0.5:.4f} m")
print("second | share of squared error | samples | worst m | top ball speed m/s | seen by the robot | behind ms | goal")
for s, w in sorted(windows.items(), key=lambda kv: -kv[1]["sq"])[:top]:
    print(
        f"{s} | {100 * w['sq'] / total_sq:.1f}% | {w['n']} | {w['max']:.3f} | {w['speed']:.2f} | "
        f"{w['seen']}/{w['n']} | {w['behind']:.1f} | {'yes' if s in goals else ''}"
    )
