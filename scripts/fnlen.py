#!/usr/bin/env python3
"""The longest Rust functions under the folders given, longest first:
`lines file first-line name` per row (N rows, default 15; env N).

With --max L, exits 1 (after the rows) when a function is longer than L
lines: scripts/test.sh checks that src/cli/ (argument parsing and printing
only, issue 40) keeps every function under 60 lines.

A function runs from its `fn` line to the brace that closes it (braces in
strings and comments count too: a rough measure, good for a bound)."""

import os
import re
import sys

FN = re.compile(r"\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?fn\s+(\w+)")


def lengths(root):
    for dirpath, _, files in os.walk(root):
        for f in files:
            if not f.endswith(".rs"):
                continue
            path = os.path.join(dirpath, f)
            lines = open(path, encoding="utf-8").read().split("\n")
            i = 0
            while i < len(lines):
                m = FN.match(lines[i])
                if not m:
                    i += 1
                    continue
                depth, opened, j = 0, False, i
                while j < len(lines):
                    for ch in lines[j]:
                        if ch == "{":
                            depth += 1
                            opened = True
                        elif ch == "}":
                            depth -= 1
                    if opened and depth == 0:
                        break
                    if not opened and lines[j].rstrip().endswith(";"):
                        break
                    j += 1
                yield j - i + 1, path, i + 1, m.group(6)
                i = j + 1 if opened else i + 1


def main(argv):
    most = None
    if argv[:1] == ["--max"]:
        most, argv = int(argv[1]), argv[2:]
    rows = sorted((r for root in argv for r in lengths(root)), reverse=True)
    for r in rows[: int(os.environ.get("N", "15"))]:
        print(*r)
    if most is not None and rows and rows[0][0] > most:
        print(f"fnlen: {rows[0][1]}:{rows[0][2]} {rows[0][3]} is {rows[0][0]} lines, over {most}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
