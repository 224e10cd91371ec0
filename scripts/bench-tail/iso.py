#!/usr/bin/env python3
"""Isolated slow round trips (over p95, both neighbours under p75): how many had another
task on CPU 0, and the switch patterns of the rest.

usage: iso.py DUMP.csv SCHED.txt   (perf script of a -C 0 sched:sched_switch record)
"""
import re,bisect,sys,collections
rows=[l.strip().split(',') for l in open(sys.argv[1]) if not l.startswith('what')]
sw=[]
for line in open(sys.argv[2]):
    m=re.search(r'\s(\d+\.\d+):',line); t=float(m.group(1))*1e6
    m2=re.search(r'prev_comm=(.*?) prev_pid=(\d+).*prev_state=(\S+) ==> next_comm=(.*?) next_pid',line)
    if m2: sw.append((t,m2.group(1),m2.group(3),m2.group(4)))
sw.sort(); T=[s[0] for s in sw]
def pct(v,p): v=sorted(v); return v[int(p*(len(v)-1))]
for w in ('raw','tokio','huddle','tokio-b'):
    h=[r for r in rows if r[0]==w]
    if not h: continue
    rt=[float(r[4]) for r in h]; p50=pct(rt,.5); p75=pct(rt,.75); p95=pct(rt,.95); p99=pct(rt,.99)
    iso=[]
    for k,r in enumerate(h):
        x=float(r[4])
        if x>p95 and 0<k<len(h)-1 and h[k-1][1]==r[1]==h[k+1][1] and float(h[k-1][4])<=p75 and float(h[k+1][4])<=p75:
            iso.append(r)
    n_other=0; kinds=collections.Counter(); ex=[]
    for r in iso:
        t0=float(r[5]); t1=t0+float(r[4])
        i=bisect.bisect_left(T,t0); j=bisect.bisect_right(T,t1)
        seq=[(s[1],s[2],s[3]) for s in sw[i:j]]
        others=[s for s in seq if not any(s[2].startswith(p) for p in ('raw','tokio','huddle','swapper'))]
        if others: n_other+=1
        else:
            kinds[(len(seq), ''.join(s[1] for s in seq))]+=1
            ex.append(round(float(r[4])))
    print(w, f'p50 {p50:.1f} p95 {p95:.1f} p99 {p99:.1f}; isolated >p95: {len(iso)}, with others {n_other}; without others rtts', sorted(ex)[-15:], 'switch patterns', kinds.most_common(6))
