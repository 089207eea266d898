#!/usr/bin/env python3
"""The import graph of src/: which file names which, and its circles.

Usage: python3 scripts/imports.py [--graph] [--no-up DIR]... [--forbid A:B]... [SRC]
(SRC defaults to src)

Every path a file's code names (`use crate::a::b`, `super::c::f(..)`,
`crate::d::E` inline; comments and unit-test modules are not counted) is resolved to the deepest
module file it reaches: src/a.rs or src/a/mod.rs is `crate::a`. That
makes an arrow from the naming file to the named one. A module's own
file (mod.rs, lib.rs) stands above the files of its folder: its arrows
down to them (`pub use child::X`, `mod child;`) are not counted, theirs up
to it are. The binary's main.rs names the library as `splatray::`.

`--no-up DIR`: no file in SRC/DIR/ names SRC/DIR/mod.rs (the folder's
facade): its files name each other and what lies below them, never back
up through the module they make. `--forbid A:B`: no file in A (a folder
or a file, without `.rs`) names one in B (`io:splat`: reading and writing
know nothing of generation).

Exits 1, naming each circle (a set of files each reaching the others),
when there is one; 0 with a one-line summary otherwise. `--graph` prints
every arrow.
"""

import re
import sys
from pathlib import Path

PATH = re.compile(r"\b(crate|super|self|splatray)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")
USE = re.compile(r"\buse\s+([^;]+);", re.S)


def module_of(src: Path, f: Path) -> tuple:
    rel = f.relative_to(src).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


def strip_comments(text: str) -> str:
    # A file's unit tests (`#[cfg(test)] mod tests`, `pub(super)` or not, at its end) are not
    # part of the library's graph.
    text = re.split(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s", text)[0]
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    # String literals can hold `::` (messages); blank them out.
    return re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)


def expand(tree: str) -> list:
    """`a::{b, c::{d, e}}` as ['a::b', 'a::c::d', 'a::c::e']."""
    tree = re.sub(r"\s+", "", tree)
    i = tree.find("{")
    if i < 0:
        return [tree]
    prefix, body = tree[:i], tree[i + 1 : tree.rfind("}")]
    parts, depth, start = [], 0, 0
    for k, ch in enumerate(body):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(body[start:k])
            start = k + 1
    parts.append(body[start:])
    out = []
    for p in parts:
        if p and p != "self":
            out += [prefix + q for q in expand(p)]
        elif p == "self":
            out.append(prefix.rstrip(":"))
    return out


def resolve(path: str, here: tuple, is_mod_file: bool, modules: dict):
    """The module file `path` reaches from the module `here`, or None."""
    segs = path.split("::")
    head, rest = segs[0], segs[1:]
    if head in ("crate", "splatray"):
        base = ()
    elif head == "self":
        base = here
    elif head == "super":
        base = here[:-1]
        while rest and rest[0] == "super":
            base, rest = base[:-1], rest[1:]
    else:
        # A path relative to this module (`child::f`, in a use of it).
        base, rest = here, segs
    best = base if base in modules else None
    cur = base
    for s in rest:
        cur = cur + (s,)
        if cur in modules:
            best = cur
        else:
            break
    return best


def graph(src: Path):
    files = sorted(p for p in src.rglob("*.rs"))
    modules = {}
    for f in files:
        modules.setdefault(module_of(src, f), f)
    arrows = {}
    for f in files:
        here = module_of(src, f)
        is_mod_file = f.name in ("mod.rs", "lib.rs", "main.rs")
        code = strip_comments(f.read_text())
        paths = [m.group(1) + m.group(2) for m in PATH.finditer(code)]
        for u in USE.finditer(code):
            paths += [p for p in expand(u.group(1)) if p]
        for p in paths:
            to = resolve(p, here, is_mod_file, modules)
            if to is None or to == here:
                continue
            if f.name == "main.rs" and p.split("::")[0] != "splatray":
                continue
            # A module's own file above its folder: no arrow down.
            if is_mod_file and to[: len(here)] == here:
                continue
            arrows.setdefault(str(f.relative_to(src)), set()).add(
                str(modules[to].relative_to(src))
            )
    return arrows


def circles(arrows: dict) -> list:
    """Strongly connected components of more than one file (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(arrows.get(v, ())):
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

    sys.setrecursionlimit(10000)
    for v in sorted(set(arrows) | {w for ws in arrows.values() for w in ws}):
        if v not in index:
            visit(v)
    return out


def rule_breaks(arrows: dict, no_up: list, forbid: list) -> list:
    """Arrows that break a `--no-up` or `--forbid` rule, described."""
    def under(f, d):
        return f == d + ".rs" or f.startswith(d.rstrip("/") + "/")

    out = []
    for a in sorted(arrows):
        for b in sorted(arrows[a]):
            for d in no_up:
                facade = d.rstrip("/") + "/mod.rs"
                if under(a, d) and a != facade and b == facade:
                    out.append(f"{a} -> {b} runs back up through {d}'s facade")
            for x, y in forbid:
                if under(a, x) and under(b, y):
                    out.append(f"{a} -> {b}: {x} may not name {y}")
    return out


def main(argv):
    show = "--graph" in argv
    no_up, forbid, args = [], [], []
    it = iter(a for a in argv if a != "--graph")
    for a in it:
        if a == "--no-up":
            no_up.append(next(it))
        elif a == "--forbid":
            x, _, y = next(it).partition(":")
            forbid.append((x, y))
        else:
            args.append(a)
    src = Path(args[0] if args else "src")
    if not src.is_dir():
        print(f"imports.py: no folder {src}", file=sys.stderr)
        return 2
    arrows = graph(src)
    if show:
        for a in sorted(arrows):
            for b in sorted(arrows[a]):
                print(f"{a} -> {b}")
    found = circles(arrows)
    n = sum(len(v) for v in arrows.values())
    broken = rule_breaks(arrows, no_up, forbid)
    for c in found:
        ties = [f"{a} -> {b}" for a in c for b in sorted(arrows.get(a, ())) if b in c]
        print(f"circle of {len(c)} files: {', '.join(c)} ({'; '.join(ties)})")
    for b in broken:
        print(b)
    if found or broken:
        return 1
    rules = len(no_up) + len(forbid)
    print(f"{len(arrows)} files, {n} arrows, no circle" + (f", {rules} rules kept" if rules else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
