#!/usr/bin/env python3
"""Why the first slot of each lost message was refused by the rules (round 15 of #33).

usage: rules_refusals.py SCENE_DIAG_OUTPUT...

For each lost message `lost_causes.py` puts in "slot 1 refused: refused by the rules",
reads the last `slot refused by the rules` line of the tracked frame near its start and
says which vote was missing and why: a tone more than 25 dB below the loudest tone
(DR, `DYNAMIC_RANGE` in decoder/rules.rs), a tone not present for another reason
(`weak?`: the crowd rule, when the slot had more than 10 tones present before it), or
rival basics (two basics of a group at 2 of 3). Prints one line per message, then counts.
"""
import sys,re,glob
sys.path.insert(0, __import__('os').path.dirname(__file__))
import lost_causes as lc
TONE=re.compile(r"(\*?)k(\d+) (-?[\d.]+) \((-?[\d.]+)\|(-?[\d.]+)\)")
from collections import Counter
cnt=Counter()
for f in sys.argv[1:]:
    for b in lc.parse(f):
        c,err=lc.classify(b)
        if 'rules' not in c: continue
        s,d=b['sender'],b['value']
        # last "found" of (s,d) near t, and the rules line that follows it
        best=None; lastfound=None
        for at,w in b['events']:
            if w.startswith('found'):
                lastfound=lc.frame_of(w)
            if w.startswith('slot refused by the rules') and lastfound==(s,d) and abs(at-b['t'])<0.3:
                best=(at,w)
        if not best: print(f,b['t'],'?'); continue
        at,w=best
        votes=eval(w.split('votes per basic ')[1].split(' tones')[0])
        loud=float(w.split('loudest k')[1].split(' ')[1])
        crowd=int(w.split('present ')[1].split(' ')[0])
        tones={int(m.group(2)):(m.group(1)=='*',float(m.group(3))) for m in TONE.finditer(w)}
        sb,db=s,3+d
        why=[]
        for name,basic in (('sender',sb),('data',db)):
            if votes[basic]<2:
                ks=[basic+24*i for i in range(3)]
                ab=[k for k in ks if not tones[k][0]]
                reasons=[]
                for k in ab:
                    lev=tones[k][1]
                    if lev<0.003162*loud: reasons.append('DR(%.1f<%.1f)'%(lev,0.003162*loud))
                    elif crowd>10: reasons.append('crowd?(%.1f)'%lev)
                    else: reasons.append('weak?(%.1f)'%lev)
                why.append('%s vote %d: %s'%(name,votes[basic],' '.join(reasons)))
        ss=[i for i in range(3) if votes[i]>=2]; dd=[i for i in range(3,24) if votes[i]>=2]
        if len(ss)>1: why.append('rival sender %s'%ss)
        if len(dd)>1: why.append('rival data %s'%[x-3 for x in dd])
        if votes[sb]>=2 and votes[db]>=2 and len(ss)<=1 and len(dd)<=1: why.append('both vote, one each: not clear?')
        key=';'.join(sorted(set(re.sub(r'\(.*?\)','',x) for x in why)))
        cnt[key]+=1
        print('%s %.2f s%d d%d @%.2f: %s | present %d loud %.0f | %s'%(f,b['t'],s,d,at,'; '.join(why),crowd,loud,' '.join('%s%d:%.1f'%('*' if p else '',k,l) for k,(p,l) in sorted(tones.items()))))
for k,v in cnt.most_common(): print(v,k)
