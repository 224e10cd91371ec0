#!/usr/bin/env python3
"""Round 23 (#33): classifies the messages `scene_diag` lists as missed by where the decoder
lost them (never found, first slot, second slot after a passed first) and the first refusal
in the trace after that point. usage: acoustic-round23-classify.py SCENE_DIAG_OUTPUT...
"""
import sys, re, collections
tot = collections.Counter(); ex = collections.defaultdict(list)
for fn in sys.argv[1:]:
    blocks = []; cur = None
    for line in open(fn):
        if line.startswith('  missed'):
            cur = [line]; blocks.append(cur)
        elif line.startswith('      ') and cur is not None:
            cur.append(line)
        else: cur = None
    for b in blocks:
        head = b[0]
        m = re.search(r'(short|long) sender=(\d) data=(\d+) at ([\d.]+) s', head)
        kind, v, at = m.group(1), int(m.group(3)), float(m.group(4))
        rep = kind == 'long' and v // 21 == v % 21
        lines = [l.strip() for l in b[1:]]
        # stage
        i2 = next((i for i,l in enumerate(lines) if 'end test after slot 1: Continues' in l), None)
        def reason(ls):
            for l in ls:
                mm = re.search(r'^[\d.]+ slot Frame \{[^}]*\} level [\d.]+ dB: ([^\[]*)', l)
                if mm: return mm.group(1).strip()
                for key in ['slot refused by the rules','slot refused: frame energy','slot refused: sender','second slot: sender does not hold its level','late check after slot 2: stopped false','late check after slot 2','first slot continues an earlier frame','end test after slot 2: Stopped']:
                    if key in l and 'search:' not in l: return key
            return '?'
        if i2 is not None:
            r = reason(lines[i2+1:]); 
            if r == 'passes':
                r2 = reason([l for l in lines[i2+1:] if 'passes' not in l]); r = 'passes then ' + r2
            st = 'slot2'
        elif any(' found ' in l for l in lines):
            st = 'slot1'; r = reason(lines)
        else:
            st = 'never found'; r = ''
        key = (st, r)
        tot[key] += 1; ex[key].append(f'{fn}:{at}{" REP" if rep else ""}')
for k, n in sorted(tot.items(), key=lambda x: -x[1]):
    print(f'{n:4} {k}  e.g. {ex[k][:3]}')
print('total', sum(tot.values()))
