#!/usr/bin/env python3
"""Import circles between the modules of one crate, at every level of its folders.

    python3 scripts/module_cycles.py crates/splatraj-experiment/src [-v]
    python3 scripts/module_cycles.py crates/*/src src       # several crates: each on its own

A file's module path comes from where it lies (`a/b.rs` and `a/b/mod.rs` are `a::b`). Every
path it names, `crate::x::y`, `super::y` (from `a::b`, that is `a::y`) or `self::y`, is
resolved to a module path; an edge goes between the two modules that hold the file and the
path right below their deepest common module: siblings, at any level (`formats::inria_ply ->
formats::ply_writer`, `decide -> tiles`). Comments and `#[cfg(test)] mod tests` are left out.
Prints, per crate, the number of modules and edges (`-v`: every edge), then each circle (a
strongly connected component of more than one sibling) with its inner edges, or "no cycle".
Exits 1 when any crate has a circle.
"""
import os
import re
import sys


def module_files(root):
    """Module path (tuple) -> its files; `lib.rs`/`main.rs` are the crate root `()`."""
    found = {}
    for folder, _, files in os.walk(root):
        for name in files:
            if not name.endswith(".rs"):
                continue
            path = os.path.join(folder, name)
            parts = os.path.relpath(path, root)[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib", "main"):
                parts = parts[:-1]
            found.setdefault(tuple(parts), []).append(path)
    return found


PATH = re.compile(r"\b(crate|super|self)((?:::[A-Za-z_][A-Za-z0-9_]*)+|::\{)")


def referenced(module, text):
    """Module paths (tuples, maybe ending in an item name) named in `text` of `module`."""
    out = []
    for match in PATH.finditer(text):
        head, tail = match.group(1), match.group(2)
        names = [n for n in tail.split("::") if n and n != "{"]
        if tail == "::{" or text[match.end():match.end() + 3] == "::{":
            # `crate::{a, b}` or `super::x::{a, b}`: each name of the group.
            start = text.index("{", match.end() - 1)
            end = text.find("}", start)
            group = re.findall(r"(?:^|,)\s*([A-Za-z_][A-Za-z0-9_]*)", text[start + 1:end])
        else:
            group = [None]
        if head == "crate":
            base = []
        elif head == "super":
            base = list(module[:-1])
            while names and names[0] == "super":
                names.pop(0)
                base = base[:-1]
        else:
            base = list(module)
        for g in group:
            out.append(tuple(base + names + ([g] if g else [])))
    return out


def level_graphs(found):
    """Parent module -> {child -> set of sibling children it names}."""
    graphs = {}
    for parent in found:
        if any(len(m) == len(parent) + 1 and m[:len(parent)] == parent for m in found):
            graphs[parent] = {m[-1]: set() for m in found
                              if len(m) == len(parent) + 1 and m[:len(parent)] == parent}
    for module, files in found.items():
        for path in files:
            text = open(path, encoding="utf-8").read()
            text = re.split(r"#\[cfg\(test\)\]\s*mod tests", text)[0]
            text = re.sub(r"//.*", "", text)
            for target in referenced(module, text):
                common = 0
                while (common < len(module) and common < len(target)
                       and module[common] == target[common]):
                    common += 1
                if common >= len(module) or common >= len(target):
                    continue  # a module naming itself, an ancestor or a descendant
                parent = module[:common]
                siblings = graphs.get(parent, {})
                source, dest = module[common], target[common]
                if source in siblings and dest in siblings and source != dest:
                    siblings[source].add(dest)
    return graphs


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


def check(root, verbose):
    """Prints `root`'s modules, edges and circles; True when it has a circle."""
    graphs = level_graphs(module_files(root))
    modules = sum(len(g) for g in graphs.values())
    edge_count = sum(len(e) for g in graphs.values() for e in g.values())
    print(f"{root}: {modules} modules, {edge_count} edges")
    found_any = False
    for parent in sorted(graphs):
        graph = graphs[parent]
        prefix = "".join(p + "::" for p in parent)
        if verbose:
            for m in sorted(graph):
                print(f"  {prefix}{m} -> {', '.join(sorted(graph[m])) or '-'}")
        for component in cycles(graph):
            found_any = True
            print(f"cycle of {len(component)}: {', '.join(prefix + m for m in component)}")
            for m in component:
                inner = sorted(prefix + n for n in graph[m] if n in component)
                print(f"   {prefix}{m} -> {', '.join(inner)}")
    if not found_any:
        print("no cycle")
    return found_any


def main():
    roots = [a for a in sys.argv[1:] if a != "-v"]
    if not roots:
        print(__doc__)
        return 2
    failed = [check(root, "-v" in sys.argv) for root in roots]
    return 1 if any(failed) else 0


if __name__ == "__main__":
    sys.exit(main())
