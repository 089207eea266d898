#!/usr/bin/env python3
"""Counts the library's public API: the items a program depending on
splatray (without the `internals` feature) can name, from the HTML that
`cargo doc --no-deps -p splatray` writes into DOC (target/doc/splatray,
removed before the build so no stale page counts). Prints the count, and
with --max N exits 1 when it is above N (scripts/test.sh: at most 150,
issue 56). -v lists what was counted.

What counts, one each:
  - an item with its own page: module (other than the crate's root),
    struct, enum, union, trait, function, type alias, constant, static,
    macro (whether defined at its path or re-exported there);
  - an inherent associated item of a struct, enum or union (a method, an
    associated constant or type, in its "Implementations" section);
  - an item a trait declares (required or provided method, associated
    constant or type).
What does not: struct fields and enum variants (part of their type's
page); methods of trait implementations (`Clone::clone`, ... : the
trait's, not splatray's); redirect pages (rustdoc writes one at a
re-exported item's private path; it names the same item).

Rustdoc's HTML is not a stable format: the markers below are checked on
every page (an item page without its `<h1>` title, a type page whose
sections are not found) so a change of format stops the count instead of
miscounting."""

import os
import re
import sys

KINDS = ("struct", "enum", "union", "trait", "fn", "type", "constant", "static", "macro",
         "traitalias", "derive", "attr")
PAGE = re.compile(r"^(%s)\.(\w+)\.html$" % "|".join(KINDS))
ASSOC = re.compile(r'<section id="((?:method|associatedconstant|associatedtype|tymethod)\.\w+)"')
SECTIONS_END = re.compile(
    r'id="(trait-implementations|synthetic-implementations|blanket-implementations|'
    r'implementors|dyn-compatibility|object-safety)"')


def count(doc, verbose):
    items = []
    for dirpath, _, files in os.walk(doc):
        rel = os.path.relpath(dirpath, doc)
        module = "" if rel == "." else rel.replace(os.sep, "::")
        for f in sorted(files):
            path = os.path.join(dirpath, f)
            if not f.endswith(".html"):
                continue
            html = open(path, encoding="utf-8").read()
            if 'http-equiv="refresh"' in html:
                continue
            if f == "index.html":
                if module:
                    items.append(("mod", module))
                continue
            m = PAGE.match(f)
            if not m:
                continue  # all.html and other listings
            kind, name = m.groups()
            if "<h1" not in html:
                sys.exit(f"api_count: {path} has no <h1> title: rustdoc's format changed?")
            full = f"{module}::{name}" if module else name
            items.append((kind, full))
            if kind in ("struct", "enum", "union", "trait"):
                body = html
                if kind != "trait":
                    start = html.find('id="implementations"')
                    if start < 0:
                        # A type with no inherent impl has no such section.
                        continue
                    end = SECTIONS_END.search(html, start)
                    if end is None:
                        sys.exit(f"api_count: {path}: no end of its implementations section")
                    body = html[start:end.start()]
                else:
                    end = SECTIONS_END.search(html)
                    body = html if end is None else html[:end.start()]
                for a in sorted(set(ASSOC.findall(body))):
                    items.append(("assoc", f"{full}::{a.split('.', 1)[1]}"))
    if verbose:
        for kind, name in sorted(items, key=lambda x: x[1]):
            print(f"  {kind:10} {name}")
    return len(items)


def main():
    args = sys.argv[1:]
    verbose = "-v" in args
    args = [a for a in args if a != "-v"]
    limit = None
    if len(args) >= 2 and args[0] == "--max":
        limit = int(args[1])
        args = args[2:]
    if len(args) != 1 or not os.path.isfile(os.path.join(args[0], "index.html")):
        sys.exit("usage: api_count.py [--max N] [-v] target/doc/splatray")
    n = count(args[0], verbose)
    print(f"public API: {n} items" + (f" (at most {limit})" if limit is not None else ""))
    if limit is not None and n > limit:
        sys.exit(f"api_count: {n} public items, above the bound of {limit}")


if __name__ == "__main__":
    main()
