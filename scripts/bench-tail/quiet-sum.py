#!/usr/bin/env python3
"""Summarise a scripts/bench-tail/quiet.sh run: huddle p50/p99 over bare tokio per round against the
62fcbd7 build, updates/s ratio, and the simulator's sim_speed_x and CPU-time ratios."""
import json, sys, glob, os, statistics as st
d = sys.argv[1]
def L(p):
    try: return open(p).read().strip()
    except: return '?'
print('| round | load | tokio p50/p99 | huddle p50/p99 | p50/tokio | p99/tokio | upd/s | old p50/tokio, p99/tokio, upd/s | upd ratio |')
print('|---|---|---|---|---|---|---|---|---|')
p50s=[];p99s=[]
for r in range(1,50):
    f=f'{d}/comms-{r}-new.json'
    if not os.path.exists(f): break
    try:
        n=json.load(open(f)); o=json.load(open(f'{d}/comms-{r}-old.json'))
    except Exception as e:
        print(r,'bad',e); continue
    a=n['huddle_p50_us']/n['tokio_p50_us']; b=n['huddle_p99_us']/n['tokio_p99_us']
    oa=o['huddle_p50_us']/o['tokio_p50_us']; ob=o['huddle_p99_us']/o['tokio_p99_us']
    p50s.append(a);p99s.append(b)
    print(f"| {r} | {L(f'{d}/comms-{r}-new.load')} | {n['tokio_p50_us']:.1f} / {n['tokio_p99_us']:.1f} | {n['huddle_p50_us']:.1f} / {n['huddle_p99_us']:.1f} | {a:.3f} | {b:.3f} | {n['updates_per_s']/1e6:.2f} M | {oa:.3f}, {ob:.3f}, {o['updates_per_s']/1e6:.2f} M | {n['updates_per_s']/o['updates_per_s']:.2f} |")
if p50s:
    print(f"p50<=1.15: {sum(x<=1.15 for x in p50s)}/{len(p50s)} med {st.median(p50s):.3f}; p99<=1.5: {sum(x<=1.5 for x in p99s)}/{len(p99s)} med {st.median(p99s):.3f}")
rat={1:[],2:[],3:[]}; cpu={1:[],2:[],3:[]}
for r in range(1,50):
    for s in (1,2,3):
        f=f'{d}/sim-{r}-{s}-new.json'
        if not os.path.exists(f): continue
        try:
            n=json.load(open(f)); o=json.load(open(f'{d}/sim-{r}-{s}-old.json'))
            def g(x):
                for k in ('sim_speed_x',):
                    if k in x: return x[k]
                return x.get('timing',{}).get('sim_speed_x')
            rat[s].append(g(n)/g(o))
            tn=sum(map(float,open(f'{d}/sim-{r}-{s}-new.time').read().split()[-2:]))
            to=sum(map(float,open(f'{d}/sim-{r}-{s}-old.time').read().split()[-2:]))
            cpu[s].append(to/tn)
        except Exception as e: print('sim',r,s,'bad',e)
for s in (1,2,3):
    if rat[s]: print(f"seed {s}: speed ratio {[round(x,2) for x in rat[s]]} med {st.median(rat[s]):.2f}; cpu ratio {[round(x,2) for x in cpu[s]]} med {st.median(cpu[s]):.2f}")
allr=sum(rat.values(),[]); allc=sum(cpu.values(),[])
if allr: print(f"speed>=2: {sum(x>=2 for x in allr)}/{len(allr)}; cpu>=2: {sum(x>=2 for x in allc)}/{len(allc)} med {st.median(allc):.3f}")
