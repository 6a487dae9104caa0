#!/usr/bin/env python3
"""Module cycles of levelmap's crates: for each crate folder given, the top-level modules of
its src/ that import each other round a circle (`crate::module` paths, test files and
`mod tests` left out). Prints each cycle and exits 1 if any crate has one (.ci/run,
"dependency rules"). Also checks that the modules named after `--leaf` (CRATE:MODULE) import
nothing of their crate.

Usage: module-cycles.py [--leaf services/mapper:config ...] services/CRATE ..."""
import os
import re
import sys

PATH = re.compile(r"\bcrate::([a-z_][a-z0-9_]*)")
GROUP = re.compile(r"\buse\s+crate::\{([^;]*)\}", re.S)


def imports(src):
    """Each top-level module of `src` and the crate's modules it names."""
    edges = {}
    for folder, _, files in os.walk(src):
        if "/tests" in folder[len(src):]:
            continue
        for name in files:
            if not name.endswith(".rs") or name == "tests.rs":
                continue
            path = os.path.join(folder, name)
            module = os.path.relpath(path, src)[:-3].split(os.sep)[0]
            if module in ("lib", "main"):
                continue
            text = open(path, encoding="utf-8").read()
            text = re.split(r"#\[cfg\(test\)\]\s*mod\s+tests", text)[0]
            text = "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))
            named = set(PATH.findall(text))
            for group in GROUP.findall(text):
                named |= set(re.findall(r"(?:^|[,{\s])([a-z_][a-z0-9_]*)\s*(?:::|,|}|$)", group))
            known = {m for m in named if os.path.exists(os.path.join(src, m + ".rs"))
                     or os.path.isdir(os.path.join(src, m))}
            edges.setdefault(module, set()).update(known - {module})
    return edges


def cycles(edges):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def main(argv):
    leaves, crates = [], []
    args = iter(argv)
    for arg in args:
        if arg == "--leaf":
            leaves.append(next(args))
        else:
            crates.append(arg)
    failed = False
    for crate in crates:
        edges = imports(os.path.join(crate, "src"))
        for component in cycles(edges):
            print(f"{crate}: modules in a circle: {' '.join(component)}")
            failed = True
    for leaf in leaves:
        crate, module = leaf.split(":")
        named = imports(os.path.join(crate, "src")).get(module, set())
        if named:
            print(f"{crate}: {module} is to be a leaf, yet imports {' '.join(sorted(named))}")
            failed = True
    if not failed:
        print(f"no module cycles in {len(crates)} crates; leaves: {' '.join(leaves) or 'none'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
