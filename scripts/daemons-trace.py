#!/usr/bin/env python3
"""Where a `huddle sim --daemons` run's team-ball error comes from (#27).

    HUDDLE_DAEMONS_TRACE=1 huddle sim --daemons ... 2> trace.txt
    scripts/daemons-trace.py trace.txt [TOP]
    scripts/daemons-trace.py --pose trace.txt

With --pose: each robot's pose RMSE through its daemon and in the in-process run of the
same seed (the `pose` and `inproc pose` lines), the share of samples off by more than
0.2 m, and how often the robot's body touched a teammate's or an opponent's (centres
within 0.45 m) or stood at the boards: in the drawn world odometry sees only part of a
shove, so pose errors come from bodies pressing on each other.

Prints the run's RMSE from the trace, then the TOP (default 5) one-second windows by their
share of the squared error, each with its samples, worst error, ball speed, how many of
the samples the robot saw the ball itself, how far the world ran behind the wall clock,
and whether a goal fell in it.
"""
import re
import sys
from collections import defaultdict



def pose_report(path):
    line_re = re.compile(
        r"(inproc )?pose t=([\d.]+) robot=(\d+) err=([\d.]+) .*at=([-\d.]+),([-\d.]+) gaps=\(([\d.]+|inf), ([\d.]+|inf)\)"
    )
    runs = {"daemons": defaultdict(lambda: defaultdict(float)), "in process": defaultdict(lambda: defaultdict(float))}
    for line in open(path):
        m = line_re.match(line)
        if not m:
            continue
        inproc, _t, robot, err, x, y, mate, opp = m.groups()
        r = runs["in process" if inproc else "daemons"][int(robot)]
        err = float(err)
        r["n"] += 1
        r["sq"] += err * err
        r["off"] += err > 0.2
        r["mate"] += float(mate) < 0.45
        r["opp"] += float(opp) < 0.45
        r["boards"] += abs(float(x)) >= 4.85 or abs(float(y)) >= 3.35
    if not runs["daemons"]:
        sys.exit(f"{path}: no pose lines (was HUDDLE_DAEMONS_TRACE=1 set?)")
    print("run | robot | pose RMSE m | off > 0.2 m | touching a teammate | an opponent | at the boards")
    for name, robots in runs.items():
        total = defaultdict(float)
        for robot in sorted(robots):
            r = robots[robot]
            for k, v in r.items():
                total[k] += v
            print(row(name, robot, r))
        print(row(name, "all", total))


def row(name, robot, r):
    n = r["n"]
    return (
        f"{name} | {robot} | {(r['sq'] / n) ** 0.5:.4f} | {100 * r['off'] / n:.1f}% | "
        f"{100 * r['mate'] / n:.1f}% | {100 * r['opp'] / n:.1f}% | {100 * r['boards'] / n:.1f}%"
    )


if sys.argv[1] == "--pose":
    pose_report(sys.argv[2])
    sys.exit(0)
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
