#!/usr/bin/env python3
"""Attribute slow round trips: dump CSV (+ optional `perf script` of sched_switch on CPU 0).

usage: tail.py DUMP.csv [SCHED.txt]
SCHED.txt: perf script -F tid,cpu,time,event,trace  (perf record -k CLOCK_MONOTONIC -C 0
           -e sched:sched_switch)
"""
import sys, bisect, collections, re

def pct(v, p):
    v = sorted(v); i = min(len(v) - 1, max(0, int(round(p * (len(v) - 1)))))
    return v[i]

rows = collections.defaultdict(list)
for line in open(sys.argv[1]):
    if line.startswith('what'):
        continue
    w, b, i, st, rtt, mono = line.strip().split(',')
    rows[w].append((int(b), int(i), float(st), float(rtt), float(mono)))

sw = []  # (time_us, prev_comm, prev_tid, next_comm, next_tid)
if len(sys.argv) > 2:
    pat = re.compile(r'prev_comm=(.*?) prev_pid=(\d+) .*?next_comm=(.*?) next_pid=(\d+)')
    for line in open(sys.argv[2]):
        if 'sched_switch' not in line:
            continue
        m = re.search(r'\s(\d+\.\d+):', line)
        t = float(m.group(1)) * 1e6
        m2 = pat.search(line)
        if not m2:
            continue
        sw.append((t, m2.group(1), int(m2.group(2)), m2.group(3), int(m2.group(4))))
    sw.sort()
times = [s[0] for s in sw]

OWN = ('raw-ping', 'raw-pong', 'tokio-ping', 'tokio-pong', 'huddle-ping', 'huddle-pong', 'swapper/0')

def inside(t0, t1):
    """who ran on CPU 0 during [t0, t1]: dict comm -> us"""
    ran = collections.Counter()
    if not sw:
        return ran, 0
    i = bisect.bisect_right(times, t0) - 1
    cur = sw[i][3] if i >= 0 else '?'
    t = t0
    n = 0
    j = i + 1
    while j < len(sw) and sw[j][0] < t1:
        ran[cur] += sw[j][0] - t
        t = sw[j][0]; cur = sw[j][3]; n += 1; j += 1
    ran[cur] += t1 - t
    return ran, n

for w, v in rows.items():
    rt = [r[3] for r in v]
    p50, p95, p99 = pct(rt, .5), pct(rt, .95), pct(rt, .99)
    slow = [r for r in v if r[3] > p95]
    print(f'== {w}: n={len(v)} p50={p50:.1f} p95={p95:.1f} p99={p99:.1f} max={max(rt):.0f}')
    # position in block
    per_block = max(r[1] for r in v) + 1
    hist = collections.Counter(min(r[1] * 10 // per_block, 9) for r in slow)
    print('  slow (>p95) by tenth of block:', [hist[k] for k in range(10)])
    print('  slow at index 0..4:', sum(1 for r in slow if r[1] < 5))
    # bursts: slow following slow within 3 indices
    idx = set((r[0], r[1]) for r in slow)
    burst = sum(1 for (b, i) in idx if any((b, i - k) in idx for k in (1, 2, 3)))
    print(f'  slow with another slow 1-3 before: {burst} of {len(slow)}')
    if sw:
        foreign_slow = collections.Counter(); fs = []; nsw = []
        own_excess = []
        for r in slow:
            ran, n = inside(r[4], r[4] + r[3])
            f = sum(us for c, us in ran.items() if c not in OWN)
            fs.append(f); nsw.append(n)
            for c, us in ran.items():
                if c not in OWN:
                    foreign_slow[c] += us
            own_excess.append(r[3] - p50 - f)
        expl = sum(1 for r, f in zip(slow, fs) if f > 0.5 * (r[3] - p50))
        print(f'  slow: others ran on CPU0 in {sum(1 for f in fs if f > 0)} of {len(slow)};'
              f' others explain >half the excess in {expl}; median own excess {pct(own_excess, .5):.1f}us')
        print('  top others in slow:', foreign_slow.most_common(8))
        # normal ones for comparison
        norm = [r for r in v if r[3] <= p50][:2000]
        fn = [sum(us for c, us in inside(r[4], r[4] + r[3])[0].items() if c not in OWN) for r in norm]
        print(f'  normal (<=p50): others ran in {sum(1 for f in fn if f > 0)} of {len(norm)}')
        # over p99 only
        s99 = [r for r in v if r[3] > p99]
        f99 = [sum(us for c, us in inside(r[4], r[4] + r[3])[0].items() if c not in OWN) for r in s99]
        e99 = [r[3] - p50 - f for r, f in zip(s99, f99)]
        def split(rs):
            acc = collections.defaultdict(list)
            for r in rs:
                ran, n = inside(r[4], r[4] + r[3])
                for k in ('ping', 'pong'):
                    acc[k].append(sum(us for c, us in ran.items() if c.endswith('-' + k)))
                acc['idle'].append(ran.get('swapper/0', 0.0))
                acc['others'].append(sum(us for c, us in ran.items() if c not in OWN))
                acc['switches'].append(n)
            return {k: round(pct(x, .5), 1) for k, x in acc.items()}, {k: round(sum(x) / len(x), 1) for k, x in acc.items()}
        print('  normal median/mean per thread:', split(norm))
        print('  slow   median/mean per thread:', split(slow))
        print(f'  >p99 ({len(s99)}): others ran in {sum(1 for f in f99 if f > 0)}; own excess median {pct(e99, .5) if e99 else 0:.1f} us; list (rtt, others):',
              [(round(r[3]), round(f)) for r, f in sorted(zip(s99, f99), key=lambda x: -x[0][3])[:12]])
