"""``python -m splatray_dask splat|render ...``: see ``--help``."""

from __future__ import annotations

import argparse
import os
import shutil
import sys

from distributed import Client, LocalCluster

from .driver import SplatrayError, render, splat


def _binary(given: str | None) -> str:
    if given:
        return given
    target = os.environ.get("CARGO_TARGET_DIR")
    if target and os.path.exists(os.path.join(target, "release", "splatray")):
        return os.path.join(target, "release", "splatray")
    found = shutil.which("splatray")
    if found:
        return found
    sys.exit("splatray-dask: no splatray binary: give --binary (the wheel's splatray command, "
             "or a clone's target/release/splatray)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m splatray_dask",
        description="splatray's tiled splat generation and renders on a Dask cluster. "
        "Options after -- are passed to every splatray command, e.g. "
        "`splat a.laz b.laz -o s.ply -- --max-memory 4`.",
    )
    ap.add_argument("--scheduler", help="tcp://HOST:8786 of a running Dask scheduler (default: a LocalCluster on this machine)")
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (without --scheduler)")
    ap.add_argument("--binary", help="the splatray binary every worker runs (same path on every node)")
    sub = ap.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("splat", help="points to splats, one task per tile")
    sp.add_argument("inputs", nargs="+")
    sp.add_argument("-o", "--output", required=True)
    sp.add_argument("--report", help="write the merge's JSON report here")
    rp = sub.add_parser("render", help="a scene or cloud to an image, one task per band of rows")
    rp.add_argument("scene")
    rp.add_argument("-o", "--output", required=True)
    rp.add_argument("--bands", type=int, help="bands of rows (default: one per worker)")
    argv = list(sys.argv[1:] if argv is None else argv)
    extra: list[str] = []
    if "--" in argv:
        at = argv.index("--")
        argv, extra = argv[:at], argv[at + 1 :]
    args = ap.parse_args(argv)
    binary = _binary(args.binary)
    if args.scheduler:
        client = Client(args.scheduler)
    else:
        client = Client(LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True))
    try:
        if args.command == "splat":
            splat(client, binary, args.inputs, args.output, extra, report=args.report)
        else:
            render(client, binary, args.scene, args.output, extra, bands=args.bands)
    except SplatrayError as e:
        print(f"splatray-dask: {e}", file=sys.stderr)
        return 1
    finally:
        client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
