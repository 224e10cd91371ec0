import re,sys,os,itertools
def graph(dirpath, prefix_re, modname_of):
    g={}
    for f in sorted(os.listdir(dirpath)):
        if not f.endswith('.rs'): continue
        src=open(os.path.join(dirpath,f)).read()
        # cut test module
        m=re.search(r'#\[cfg\(test\)\]\s*(pub\s+)?mod\s+\w+\s*\{',src)
        body=src[:m.start()] if m else src
        body=re.sub(r'//.*','',body)
        me=modname_of(f)
        deps=set(re.findall(prefix_re,body))
        deps.discard(me)
        g[me]=deps
    return g
def cycles(g):
    out=[]
    for a in g:
        for b in g[a]:
            if b in g and a in g[b] and a<b: out.append((a,b))
    # longer cycles via DFS
    import collections
    idx={};low={};st=[];on=set();res=[];c=[0]
    def sc(v):
        idx[v]=low[v]=c[0];c[0]+=1;st.append(v);on.add(v)
        for w in g.get(v,()):
            if w not in g: continue
            if w not in idx: sc(w);low[v]=min(low[v],low[w])
            elif w in on: low[v]=min(low[v],idx[w])
        if low[v]==idx[v]:
            comp=[]
            while True:
                w=st.pop();on.discard(w);comp.append(w)
                if w==v:break
            if len(comp)>1: res.append(comp)
    for v in g:
        if v not in idx: sc(v)
    return out,res
name=lambda f: f[:-3]
g=graph('driver/src', r'crate::([a-z_]+)', name)
print('driver', {k:sorted(v) for k,v in g.items() if v}); print(cycles(g))
g=graph('src/cli', r'(?:super|crate::cli)::([a-z_]+)', lambda f: 'mod' if f=='mod.rs' else f[:-3])
print('cli', {k:sorted(v) for k,v in g.items() if v}); print(cycles(g))
