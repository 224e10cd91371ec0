#!/usr/bin/env python3
"""The decoder's losses split by the oracle-timing reference (round 12 of #33).

usage: oracle_split.py ORACLE_DIAG_OUTPUT SCENE_DIAG_OUTPUT [--list]

`oracle_diag` says, for every sent message, whether the decoder got it and whether the
oracle (told the message's start, length and clock error; no detection step) picks it;
`scene_diag` on the same row (same build, same seed) gives the decoder's trace around each
lost message, which `lost_causes.py` classifies. Prints, per class of the decoder's
losses, how many the oracle gets (the decoder's to win: the signal is there) and how many
it loses too (not in the signal for the oracle at this airtime), and the slot-1 onset
error of each class.
"""
import os
import re
import sys
from collections import Counter, defaultdict

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from lost_causes import classify, parse  # noqa: E402

MSG = re.compile(r"msg ([\d.]+) (short|long) sender=(\d) data=(\d+) decoder=(\w+) oracle=(\w+) mean=(\w+) margin=(-?[\d.]+|NaN|inf|-inf)")


def main():
    verdicts = {}
    for line in open(sys.argv[1]):
        m = MSG.match(line)
        if m:
            verdicts[round(float(m.group(1)), 2)] = m.groups()
    by_class = defaultdict(Counter)
    errs = defaultdict(list)
    listing = []
    for b in parse(sys.argv[2]):
        c, err = classify(b)
        v = verdicts.get(round(b["t"], 2))
        o = "?" if v is None else ("oracle gets" if v[5] == "ok" else "oracle loses")
        by_class[c][o] += 1
        if err is not None:
            errs[c].append(err)
        margin = "-" if v is None else v[7]
        listing.append("%-8.2f %s %d: %s; %s (margin %s dB)%s" % (
            b["t"], b["kind"], b["value"], c, o, margin,
            "" if err is None else " onset %+.3f s" % err))
    if "--list" in sys.argv:
        print("\n".join(listing))
    total = Counter()
    print("%-55s %6s %6s" % ("decoder's loss class", "oracle", "oracle"))
    print("%-55s %6s %6s" % ("", "gets", "loses"))
    for c, n in sorted(by_class.items(), key=lambda x: -sum(x[1].values())):
        e = errs.get(c, [])
        spread = "" if not e else "  onset %+.2f…%+.2f s" % (min(e), max(e))
        print("%-55s %6d %6d%s" % (c, n["oracle gets"], n["oracle loses"], spread))
        total.update(n)
    print("%-55s %6d %6d" % ("lost by the decoder", total["oracle gets"], total["oracle loses"]))
    got_by_decoder_lost_by_oracle = sum(1 for v in verdicts.values() if v[4] == "ok" and v[5] == "lost")
    print("decoder gets, oracle loses: %d of %d sent" % (got_by_decoder_lost_by_oracle, len(verdicts)))


if __name__ == "__main__":
    main()
