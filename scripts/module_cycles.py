#!/usr/bin/env python3
"""Import circles between the modules of each crate of the workspace (STYLE.md: a circle means
two files are one concept or a shared type has no home).

A module is a top-level file or folder under a crate's `src/` (`effects/backlash.rs` belongs to
`effects`); it uses another when its code (test modules and comments left out) names
`crate::<module>`. Prints every strongly connected group of more than one module with the lines
that tie it, and exits 1 when there is one.
"""
import os
import re
import sys


def modules(src):
    """Module name -> {used module -> first line naming it}."""
    uses = {}
    for root, dirs, files in os.walk(src):
        dirs[:] = [d for d in dirs if d != "bin"]
        for f in files:
            if not f.endswith(".rs") or f in ("lib.rs", "main.rs", "tests.rs"):
                continue
            path = os.path.join(root, f)
            rel = os.path.relpath(path, src)[:-3]
            name = rel.split(os.sep)[0]
            text = open(path, encoding="utf-8").read()
            cut = text.find("#[cfg(test)]")
            if cut >= 0:
                text = text[:cut]
            mine = uses.setdefault(name, {})
            for line in text.splitlines():
                code = line.split("//")[0]
                names = re.findall(r"crate::(\w+)", code)
                for group in re.findall(r"crate::\{([^}]*)\}", code):
                    names += [g.strip().split("::")[0] for g in group.split(",") if g.strip()]
                for n in names:
                    if n != name:
                        mine.setdefault(n, "%s: %s" % (path, line.strip()))
    return {m: {u: w for u, w in us.items() if u in uses} for m, us in uses.items()}


def groups(graph):
    """Strongly connected components (Tarjan) with more than one member."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else "."
    found = 0
    for crate in sorted(os.listdir(root)):
        src = os.path.join(root, crate, "src")
        if not os.path.isdir(src):
            continue
        graph = modules(src)
        for comp in groups(graph):
            found += 1
            print("%s: modules %s use each other:" % (crate, " <-> ".join(comp)))
            for a in comp:
                for b in comp:
                    if b in graph[a]:
                        print("    %s" % graph[a][b])
    if found:
        print("%d import circle(s)" % found)
        return 1
    print("no import circles between the modules of any crate")
    return 0


if __name__ == "__main__":
    sys.exit(main())
