#!/usr/bin/env python3
"""Issue 33's bar "no import circles": within each crate, the top-level modules (the files
and folders beside lib.rs or main.rs) as a graph with an edge a -> b when code of a, outside
its test modules, names `crate::b` or reaches b through `super::` (a `use` tree's braces
followed to any depth). Prints each circle with the line that makes each of its edges;
exits 1 when there is one.

    python3 .ci/import-circles.py
"""
import re
import subprocess
import sys


def strip(text):
    """The code without comments and without what follows the first inline test module."""
    text = re.sub(r"//[^\n]*", "", text)
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    m = re.search(r"#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{", text)
    return text[: m.start()] if m else text


def heads(tree):
    """The first path segment of every path a `use` tree (text after `prefix::`) names."""
    tree = tree.strip()
    if not tree.startswith("{"):
        m = re.match(r"\w+", tree)
        return [m.group(0)] if m else []
    out, depth, item = [], 0, ""
    for ch in tree[1:]:
        if ch == "{":
            depth += 1
        elif ch == "}":
            if depth == 0:
                break
            depth -= 1
        if ch == "," and depth == 0:
            out += heads(item)
            item = ""
        else:
            item += ch
    return out + heads(item)


files = subprocess.check_output(["git", "ls-files", "*.rs"], text=True).split()
graph, why = {}, {}
for path in files:
    if "/src/" not in path or "/src/bin/" in path:
        continue
    root, rest = path.split("/src/", 1)
    parts = rest[:-3].split("/")
    if parts[-1] == "mod":
        parts = parts[:-1]
    if parts in (["lib"], ["main"]):
        continue  # the crate root names every module; it is not a sibling
    module, depth = parts[0], len(parts)
    text = strip(open(path, encoding="utf-8").read())
    prefixes = [r"crate::"] + [r"(?:super::){%d}" % depth]
    for prefix in prefixes:
        for m in re.finditer(r"(?<![\w:])" + prefix + r"(\{|\w+)", text):
            tail = text[m.start(1) : m.start(1) + 4000]
            for head in heads(tail):
                if head in ("self", "super", "crate") or head == module:
                    continue
                graph.setdefault(root, {}).setdefault(module, set()).add(head)
                line = text[: m.start()].count("\n") + 1
                why.setdefault((root, module, head), f"{path}: {m.group(0)}… (code line {line})")

circles = []
for root, edges in sorted(graph.items()):
    modules = set(edges)

    def visit(node, stack, seen):
        for nxt in sorted(edges.get(node, ())):
            if nxt not in modules:
                continue
            if nxt in stack:
                cycle = stack[stack.index(nxt) :] + [nxt]
                key = frozenset(cycle)
                if key not in seen:
                    seen.add(key)
                    circles.append((root, cycle))
            elif len(stack) < 10:
                visit(nxt, stack + [nxt], seen)

    seen = set()
    for start in sorted(modules):
        visit(start, [start], seen)

for root, cycle in circles:
    print(f"{root}: {' -> '.join(cycle)}")
    for a, b in zip(cycle, cycle[1:]):
        print(f"    {why[(root, a, b)]}")
print(f"{len(graph)} crates with module edges, {len(circles)} circles")
sys.exit(1 if circles else 0)
