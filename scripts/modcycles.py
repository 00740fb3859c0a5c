#!/usr/bin/env python3
"""Module-level import cycles inside each crate of a Cargo workspace (and the binary's src/).

A module file A depends on module B of the same crate when A names `crate::B` (in a `use` or a path) or `super::B`
from a sibling. Prints one line per strongly connected component of two or more modules, and the count last;
exits non-zero when there is any (CI runs it: layers inside a crate run one way too)."""
import os, re, sys

root = sys.argv[1] if len(sys.argv) > 1 else '.'
srcs = [os.path.join(root, 'src')] + [os.path.join(root, 'crates', c, 'src') for c in sorted(os.listdir(os.path.join(root, 'crates')))
                                      if os.path.isdir(os.path.join(root, 'crates', c, 'src'))]

def modname(src, path):
    rel = os.path.relpath(path, src)[:-3]
    parts = rel.split(os.sep)
    if parts[-1] in ('mod', 'lib', 'main'):
        parts = parts[:-1]
    return '::'.join(parts)

total = 0
for src in srcs:
    if not os.path.isdir(src):
        continue
    files = {}
    for d, _, fs in os.walk(src):
        for f in fs:
            if f.endswith('.rs'):
                p = os.path.join(d, f)
                files[modname(src, p)] = p
    mods = set(files)
    edges = {m: set() for m in mods}
    for m, p in files.items():
        text = open(p, encoding='utf-8', errors='replace').read()
        text = re.sub(r'(?s)#\[cfg\(test\)\]\s*mod\s+tests\s*\{.*', '', text)  # tests at the end of a file do not count
        names = set()
        for g in re.findall(r'\bcrate::((?:\w+::)*\w+)', text):
            names.add(g)
        for g in re.findall(r'\buse\s+crate::\{([^}]*)\}', text):
            names.update(x.strip().split('::')[0] for x in g.split(',') if x.strip())
        parent = m.rsplit('::', 1)[0] if '::' in m else ''
        for g in re.findall(r'\bsuper::((?:\w+::)*\w+)', text):
            names.add((parent + '::' + g) if parent else g)
        for n in names:
            parts = n.split('::')
            for k in range(len(parts), 0, -1):
                cand = '::'.join(parts[:k])
                if cand in mods and cand != m and cand != '':
                    edges[m].add(cand)
                    break
    # Tarjan
    index, low, stack, on, out, i = {}, {}, [], set(), [], [0]
    def strong(v):
        index[v] = low[v] = i[0]; i[0] += 1; stack.append(v); on.add(v)
        for w in edges[v]:
            if w not in index:
                strong(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: out.append(sorted(comp))
    sys.setrecursionlimit(10000)
    for v in sorted(mods):
        if v not in index: strong(v)
    for comp in out:
        total += 1
        print(f'{os.path.relpath(src, root)}: cycle of {len(comp)}: {", ".join(comp)}')
print(f'{total} module cycles')
sys.exit(1 if total else 0)
