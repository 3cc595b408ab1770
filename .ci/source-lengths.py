#!/usr/bin/env python3
"""Issue 33's bar "no source file over 800 lines before its test module": for every tracked
Rust source file, the lines before its first `#[cfg(test)]` that opens an inline module (the
attribute followed by `mod name {`), or all its lines when it has none (a test module in a
file of its own, `#[cfg(test)] mod name;`, is counted as that file). Prints the files over the
limit (default 800) and the five longest; exits 1 when any is over.

    python3 .ci/source-lengths.py [LIMIT]
"""
import re
import subprocess
import sys

limit = int(sys.argv[1]) if len(sys.argv) > 1 else 800
files = subprocess.check_output(["git", "ls-files", "*.rs"], text=True).split()
lengths = []
for path in files:
    lines = open(path, encoding="utf-8").read().split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    end = len(lines)
    for i, line in enumerate(lines):
        if line.strip() == "#[cfg(test)]":
            rest = [l.strip() for l in lines[i + 1 : i + 4] if l.strip()]
            if rest and re.match(r"(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{", rest[0]):
                end = i
                break
    lengths.append((end, len(lines), path))
lengths.sort(reverse=True)
over = [x for x in lengths if x[0] > limit]
for end, total, path in over:
    print(f"OVER {limit}: {path}: {end} lines before its tests ({total} in all)")
print("longest:")
for end, total, path in lengths[:5]:
    print(f"  {end:5} before tests, {total:5} in all  {path}")
print(f"{len(files)} files, {len(over)} over {limit}")
sys.exit(1 if over else 0)
