#!/usr/bin/env python3
"""The table of an interleaved run of measure.sh, and the counts against the targets.

usage: table.py OUT.jsonl [LABEL]
"""
import json,sys
rows=[json.loads(l) for l in open(sys.argv[1])]
label=sys.argv[2] if len(sys.argv)>2 else 'h-lat11'
print('| round | rounds | build | start | load | raw p50 | tokio p50 / p99 | huddle p50 / p99 | p50 ÷ tokio | p99 ÷ tokio | A/A: tokio-b p50 ÷ tokio, p99 ÷ tokio | updates/s |')
print('|---|---|---|---|---|---|---|---|---|---|---|---|')
pairs={}
for x in rows:
    r=x['r']; old='62fcbd7' in x['build']
    b='62fcbd7' if old else label
    p50=r['huddle_p50_us']/r['tokio_p50_us']; p99=r['huddle_p99_us']/r['tokio_p99_us']
    aa=r.get('aa'); aas=f"{aa['p50_b_over_a']:.3f}, {aa['p99_b_over_a']:.2f}" if aa else '–'
    print(f"| {x['round']} | {x['rounds']} | {b} | {x['start']} | {x['load'].replace(' ','/')} | {r['raw_p50_us']:.1f} | {r['tokio_p50_us']:.1f} / {r['tokio_p99_us']:.0f} | {r['huddle_p50_us']:.1f} / {r['huddle_p99_us']:.0f} | {p50:.3f} | {p99:.2f} | {aas} | {r['updates_per_s']/1e3:.0f} k |")
    pairs.setdefault((x['round'],x['rounds']),{})[b]=(p50,p99,r['updates_per_s'],aa)
print()
for rounds in (5000,20000):
    for b in ('62fcbd7',label):
        v=[p[b] for (i,n),p in pairs.items() if n==rounds and b in p]
        if not v: continue
        p50s=sorted(round(x[0],3) for x in v); p99s=sorted(round(x[1],2) for x in v)
        print(f"{rounds} {b}: p50<=1.15 in {sum(1 for x in v if x[0]<=1.15)} of {len(v)} {p50s}; p99<=1.5 in {sum(1 for x in v if x[1]<=1.5)} of {len(v)} {p99s}")
        aas=[x[3] for x in v if x[3]]
        if aas:
            print(f"   A/A p99 b/a: {sorted(round(a['p99_b_over_a'],2) for a in aas)}; outside [1/1.5,1.5]: {sum(1 for a in aas if not (1/1.5<=a['p99_b_over_a']<=1.5))}; p50 b/a {sorted(round(a['p50_b_over_a'],3) for a in aas)}")
    ups=[p[label][2]/p['62fcbd7'][2] for (i,n),p in pairs.items() if n==rounds and label in p and '62fcbd7' in p]
    print(f"{rounds} updates/s ratio: {sorted(round(u,2) for u in ups)}; >=1.5 in {sum(1 for u in ups if u>=1.5)} of {len(ups)}")
