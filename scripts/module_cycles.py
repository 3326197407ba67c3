#!/usr/bin/env python3
"""Import circles between the top-level modules of one crate.

    python3 scripts/module_cycles.py crates/splatraj-experiment/src [-v]

Every `crate::<module>` path in a module's files (use lines, `crate::{a, b}` groups and inline
paths; comments and `#[cfg(test)] mod tests` left out) is an edge from that module to
`<module>`. Prints the number of modules and edges (`-v`: every module's edges), then each
strongly connected component of more than one module with its inner edges, or "no cycle".
Exits 1 when there is a cycle.
"""
import os
import re
import sys


def modules(root):
    """Top-level module name -> its files (`lib.rs` is `lib`, `a/b.rs` belongs to `a`)."""
    found = {}
    for folder, _, files in os.walk(root):
        for name in files:
            if not name.endswith(".rs"):
                continue
            path = os.path.join(folder, name)
            parts = os.path.relpath(path, root)[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib"):
                parts = parts[:-1]
            found.setdefault(parts[0] if parts else "lib", []).append(path)
    return found


def edges(found):
    """Module -> the other modules it names through `crate::`."""
    out = {m: set() for m in found}
    for module, files in found.items():
        for path in files:
            text = open(path, encoding="utf-8").read()
            text = re.split(r"#\[cfg\(test\)\]\s*mod tests", text)[0]
            text = re.sub(r"//.*", "", text)
            names = re.findall(r"crate::([a-z_][a-z0-9_]*)", text)
            for group in re.findall(r"crate::\{([^}]*)\}", text):
                names += re.findall(r"(?:^|,)\s*([a-z_][a-z0-9_]*)", group)
            out[module].update(n for n in names if n in found and n != module)
    return out


def cycles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, result = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                result.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return result


def main():
    graph = edges(modules(sys.argv[1]))
    print(f"{len(graph)} modules, {sum(len(e) for e in graph.values())} edges")
    if "-v" in sys.argv:
        for m in sorted(graph):
            print(f"  {m} -> {', '.join(sorted(graph[m])) or '-'}")
    found = cycles(graph)
    if not found:
        print("no cycle")
    for component in found:
        print(f"cycle of {len(component)}: {', '.join(component)}")
        for m in component:
            inner = sorted(n for n in graph[m] if n in component)
            print(f"   {m} -> {', '.join(inner)}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
