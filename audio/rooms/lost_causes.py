#!/usr/bin/env python3
"""Where each lost message of a `scene_diag` run fails (round 8 of #33).

usage: lost_causes.py SCENE_DIAG_OUTPUT [--list]

Reads the `missed ... at T s` blocks `scene_diag` prints (the decoder's trace around each
lost message) and puts each in one class, by the first thing that went wrong:

  first frame not found     no frame of the sender with the first frame's data was tracked
                            with an onset within 0.3 s of the message's
  first frame found off     it was, but only at an onset 0.3 s or more away
  slot 1 refused: CHECK     the first slot was decided and refused by CHECK (off grid = on
                            the frequency grid)
  slot 1 dropped: ...       passed, then dropped (continues an earlier frame, data begins later)
  end test after slot 1: V  passed, the end test did not say "continues" and the late check
                            did not rescue it
  slot 2 refused: CHECK     the second slot was decided and refused
  slot 2 level              the second slot's sender did not hold its level
  after slot 2: ...         both slots passed, the end test or late check after slot 2 failed
  other                     none of these

For a short message the same classes apply to its one frame (and "end test after slot 1"
means the end test did not say "stopped").
"""
import re
import sys
from collections import Counter

NAMES = {"Goalkeeper": 0, "LeftAttacker": 1, "RightAttacker": 2}
FRAME = re.compile(r"Frame \{ sender: (\w+), data: (\d+) \}")


def parse(path):
    blocks = []
    cur = None
    for line in open(path):
        m = re.match(r"  missed (short|long) sender=(\d) data=(\d+) at ([\d.]+) s", line)
        if m:
            cur = {
                "kind": m.group(1),
                "sender": int(m.group(2)),
                "value": int(m.group(3)),
                "t": float(m.group(4)),
                "events": [],
            }
            blocks.append(cur)
            continue
        m = re.match(r"\s+([\d.]+) (.*)", line)
        if cur is not None and m and line.startswith("      "):
            cur["events"].append((float(m.group(1)), m.group(2)))
        elif not line.startswith(" "):
            cur = None
    return blocks


def frame_of(text):
    m = FRAME.search(text)
    if not m:
        return None
    return NAMES[m.group(1)], int(m.group(2))


def classify(b, slot=1.0, near=0.3):
    s, t = b["sender"], b["t"]
    if b["kind"] == "long":
        d1, d2 = divmod(b["value"], 21)
    else:
        d1, d2 = b["value"], None
    ev = []
    last_found = None
    for at, w in b["events"]:
        if w.startswith("found"):
            last_found = w
        if w.startswith("slot refused by the rules") and last_found:
            # The rules' refusal names no frame: it is the last found one's.
            f = FRAME.search(last_found).group(0)
            w = "slot %s level ? dB: refused by the rules" % f
        ev.append((at, w))
    # Slot decisions of the first frame: data d1, onset near t.
    slots1 = [
        (at, w)
        for at, w in ev
        if w.startswith("slot ") and frame_of(w) == (s, d1) and abs(at - t) < near
    ]
    if not slots1:
        found = [at for at, w in ev if w.startswith("found") and frame_of(w) == (s, d1)]
        if any(abs(at - t) < near for at in found):
            return "first frame found, no slot decided", None
        if found:
            return "first frame found off (onset %+.2f s)" % min(
                (at - t for at in found), key=abs
            ), None
        return "first frame not found", None
    # The last decision on a first slot near t (a replay may have decided several).
    at1, w1 = slots1[-1]
    err = at1 - t
    verdict = w1.split("dB: ", 1)[1].split(" [")[0]
    if verdict != "passes":
        return "slot 1 refused: " + verdict, err
    after = [(at, w) for at, w in ev if at >= at1 - 0.05]
    idx = ev.index((at1, w1))
    rest = ev[idx + 1 :]
    for at, w in rest:
        if w.startswith("first slot continues"):
            return "slot 1 dropped: continues an earlier frame", err
        if w.startswith("first slot inside"):
            return "slot 1 dropped: data begins later", err
        if w.startswith("end test after slot 1"):
            v = w.split(": ")[1]
            if b["kind"] == "short":
                if v == "Stopped":
                    return "short: stopped yet lost (plan?)", err
                return "end test after slot 1: " + v, err
            if v == "Continues":
                break
            return "end test after slot 1: " + v, err
        if w.startswith("timeline") or w.startswith("search") or w.startswith("found"):
            continue
    else:
        return "slot 1 passed, nothing after", err
    for at, w in rest:
        if w.startswith("second slot: sender does not hold"):
            return "slot 2 level", err
        if w.startswith("slot Frame") and at > at1 + 0.5 * slot:
            verdict = w.split("dB: ", 1)[1].split(" [")[0]
            f = frame_of(w)
            if verdict != "passes":
                return "slot 2 refused: " + verdict, err
            if f != (s, d2):
                return "slot 2 wrong data", err
        if w.startswith("end test after slot 2"):
            v = w.split(": ")[1]
            if v != "Stopped":
                nxt = [x for _, x in rest if x.startswith("late check after slot 2")]
                return "after slot 2: end test %s, %s" % (v, nxt[0] if nxt else "-"), err
        if w.startswith("report"):
            return "reported other: " + w, err
    return "other", err


def main():
    blocks = parse(sys.argv[1])
    counts = Counter()
    for b in blocks:
        c, err = classify(b)
        counts[c] += 1
        if "--list" in sys.argv:
            e = "" if err is None else " (slot 1 onset %+.3f s)" % err
            print("%-7.2f %s %d: %s%s" % (b["t"], b["kind"], b["value"], c, e))
    for c, n in counts.most_common():
        print("%4d  %s" % (n, c))
    print("%4d  lost" % len(blocks))


if __name__ == "__main__":
    main()
