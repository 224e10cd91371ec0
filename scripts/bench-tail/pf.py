#!/usr/bin/env python3
"""Page faults of each ping-pong's own threads inside its measured round trips.

usage: pf.py DUMP.csv TRACE.txt   (perf script of a -C 0 record with -e page-faults -c 1)
"""
import re,bisect,sys,collections
rows=[l.strip().split(',') for l in open(sys.argv[1]) if not l.startswith('what')]
pf=collections.defaultdict(list)
for line in open(sys.argv[2]):
    if 'page-faults' in line:
        p=line.split(); comm=p[0]
        m=re.search(r'\s(\d+\.\d+):',line); pf[comm.split('-')[0] if comm.split('-')[-1] in ('ping','pong') else 'x'].append((float(m.group(1))*1e6, comm))
def pct(v,p): v=sorted(v); return v[int(p*(len(v)-1))]
for w in ('raw','tokio','huddle','tokio-b'):
    h=[r for r in rows if r[0]==w]
    key=w.split('-')[0]
    T=sorted(t for t,_ in pf.get(key,[]))
    rt=[float(r[4]) for r in h]; p50=pct(rt,.5); p99=pct(rt,.99); p95=pct(rt,.95)
    hit=[]; inblock=0
    for r in h:
        t0=float(r[5]); t1=t0+float(r[4])
        n=bisect.bisect_right(T,t1)-bisect.bisect_left(T,t0)
        if n: hit.append((round(float(r[4])),n, r[1], r[2]))
    print(w, 'faults of its threads in the run', len(T), 'in measured rtts', sum(x[1] for x in hit), 'rtts with a fault', len(hit), 'of which >p95', sum(1 for x in hit if x[0]>p95), 'p95', round(p95))
    print('   ', sorted(hit)[-20:])
