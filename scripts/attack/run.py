#!/usr/bin/env python3
"""huddle's independent attack suite: real daemons on loopback, attacked from Python.

    python3 scripts/attack/run.py --huddle target/debug/huddle            # short (< 60 s)
    python3 scripts/attack/run.py --huddle target/release/huddle --long   # minutes
    python3 scripts/attack/run.py --huddle H --old /path/to/older/huddle  # mixed team too
    python3 scripts/attack/run.py --huddle H --only gc_packets --seed 7

Each attack starts its own daemons (scratch multicast group, relay and GC ports on
127.0.0.1) and checks, after it: the process is alive and never panicked, a fresh relay
client is answered, what was stored before is still there, the counters moved as
documented, the game state never went backwards. The seed is printed (and taken from the
clock unless --seed): rerun a failure with it. docs/attack-suite.md says more.
"""

import argparse
import json
import os
import sys
import time
import traceback

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import attack_edges  # noqa: E402
import attack_gc  # noqa: E402
import attack_mixed  # noqa: E402
import attack_relay  # noqa: E402
import attack_team  # noqa: E402
import attack_wire  # noqa: E402

ATTACKS = [
    ("wire_crafted", attack_wire.crafted),
    ("wire_mutated", attack_wire.mutated),
    ("wire_keyed", attack_wire.keyed),
    ("wire_unicast", attack_wire.unicast),
    ("gc_packets", attack_gc.packets),
    ("gc_order", attack_gc.order),
    ("gc_flood", attack_gc.flood),
    ("gc_broadcast", attack_gc.broadcast),
    ("relay_lines", attack_relay.lines),
    ("relay_long_lines", attack_relay.long_lines),
    ("relay_half_lines", attack_relay.half_lines),
    ("relay_connections", attack_relay.connections),
    ("relay_client_cap", attack_relay.client_cap),
    ("relay_no_reader", attack_relay.no_reader),
    ("config_files", attack_relay.config_files),
    ("team_inputs", attack_team.inputs),
    ("mixed_future", attack_mixed.future_items),
    ("relay_line_limit", attack_edges.line_limit),
    ("relay_interleaved", attack_edges.interleaved),
    ("relay_watch_flood", attack_edges.watch_flood),
    ("relay_utf8_keys", attack_edges.utf8_keys),
    ("relay_read_only", attack_edges.read_only),
    ("gc_stale_storm", attack_edges.gc_stale_storm),
]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--huddle", required=True, help="the huddle binary under attack")
    p.add_argument("--seed", type=int, default=None, help="default: from the clock (printed)")
    p.add_argument("--long", action="store_true", help="many more frames, lines and connections")
    p.add_argument("--old", action="append", default=[], help="an older huddle binary for a mixed team (repeatable)")
    p.add_argument("--only", action="append", default=[], help="run only these attacks (repeatable)")
    p.add_argument("--json", help="write the results here")
    a = p.parse_args()
    seed = a.seed if a.seed is not None else int(time.time() * 1000) % 1_000_000
    binary = os.path.abspath(a.huddle)
    print("attack suite: %s, seed %d%s" % (binary, seed, ", long" if a.long else ""), flush=True)
    attacks = list(ATTACKS)
    for old in a.old:
        attacks.append(("mixed_old:%s" % os.path.basename(old),
                        lambda b, s, log, long, old=old: attack_mixed.mixed_team(b, os.path.abspath(old), s, log, long)))
    if a.only:
        attacks = [(n, f) for n, f in attacks if any(n.startswith(o) for o in a.only)]
    results, failed = {}, []
    started = time.monotonic()
    for name, fn in attacks:
        t = time.monotonic()
        print("[%s]" % name, flush=True)
        try:
            r = fn(binary, seed, lambda s: print(s, flush=True), a.long)
            results[name] = {"ok": True, "secs": round(time.monotonic() - t, 1), **(r or {})}
            print("[%s] ok in %.1f s" % (name, time.monotonic() - t), flush=True)
        except Exception as e:  # noqa: BLE001 - every failure is reported, then the next attack runs
            failed.append(name)
            results[name] = {"ok": False, "error": str(e)}
            traceback.print_exc()
            print("[%s] FAILED (seed %d): %s" % (name, seed, e), flush=True)
    total = time.monotonic() - started
    print("attack suite: %d attacks, %d failed, %.1f s, seed %d%s"
          % (len(attacks), len(failed), total, seed, (": " + ", ".join(failed)) if failed else ""))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"seed": seed, "long": a.long, "secs": round(total, 1), "results": results}, f, indent=2)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
