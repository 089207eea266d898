"""Plans, submits and merges splatray's tiles and bands on a Dask cluster."""

from __future__ import annotations

import ctypes
import json
import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Callable, Sequence

from distributed import Client, as_completed

PR_SET_PDEATHSIG = 1


class SplatrayError(RuntimeError):
    """A splatray command that failed; the message is its own one-line error."""


def _die_with_parent() -> None:
    # A task's process ends with the worker that started it: a killed
    # worker leaves no orphan writing into the work folder (Linux only;
    # elsewhere the orphan finishes, which is harmless: results are atomic
    # and identical).
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        pass


def run_binary(binary: str, args: Sequence[str]) -> str:
    """Runs ``binary args`` and returns the last line it printed (splatray's
    summary); raises :class:`SplatrayError` with its last line when it
    fails."""
    proc = subprocess.run(
        [binary, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
        check=False,
    )
    if proc.returncode != 0:
        lines = [l for l in proc.stderr.splitlines() if l.strip()]
        last = lines[-1] if lines else f"exit status {proc.returncode}"
        raise SplatrayError(f"splatray {' '.join(args[:1])}: {last}")
    said = [l for l in (proc.stdout + "\n" + proc.stderr).splitlines() if l.strip()]
    return said[-1] if said else ""


#: The options of ``splat`` by the Python package's names (those of
#: ``splatray.splat``, and the tiling's), each a ``splatray splat`` flag.
SPLAT_OPTIONS = (
    "epsilon", "k", "density", "ellipses", "flat_colors", "creases", "viewpoint",
    "no_viewpoint", "thin", "tile_points", "max_memory",
)
#: The options of ``render`` by the Python package's names (those of
#: ``splatray.Scene.render``), each a ``splatray render`` flag.
RENDER_OPTIONS = ("backend", "width", "height", "spp", "shading")


def options_flags(options: dict, allowed: Sequence[str], what: str) -> list[str]:
    """Keyword options as command-line flags: ``tile_points=30000`` ->
    ``--tile-points 30000``, ``ellipses=True`` -> ``--ellipses``,
    ``viewpoint=(x, y, z)`` -> ``--viewpoint x,y,z``; ``None`` and
    ``False`` give nothing, but ``creases=False``, which gives
    ``--no-creases``."""
    flags: list[str] = []
    for name, value in options.items():
        if name not in allowed:
            raise TypeError(f"{what}: unknown option {name!r} (options: {', '.join(allowed)})")
        if name == "creases" and value is False:
            # Creases are on by default: False is --no-creases.
            flags.append("--no-creases")
            continue
        if value is None or value is False:
            continue
        flag = "--" + name.replace("_", "-")
        if value is True:
            flags.append(flag)
        elif isinstance(value, (list, tuple)):
            flags += [flag, ",".join(repr(float(v)) for v in value)]
        else:
            flags += [flag, str(value)]
    return flags


def _abs(p: str | os.PathLike) -> str:
    return str(Path(p).resolve())


def _say(progress: Callable[[str], None] | None, text: str) -> None:
    if progress is not None:
        progress(text)


def _one(client: Client, binary: str, args: list[str], key: str) -> str:
    """Runs one splatray command as a task and returns its last line."""
    return client.submit(run_binary, binary, args, key=key, pure=False).result()


def _fan_out(
    client: Client,
    binary: str,
    jobs: list[tuple[str, list[str]]],
    progress: Callable[[str], None] | None,
) -> None:
    """Runs ``(key, args)`` jobs as tasks (Dask reruns one whose worker
    died, and retries a failed one twice), saying each as it finishes."""
    futs = [
        client.submit(run_binary, binary, args, key=key, pure=False, retries=2)
        for key, args in jobs
    ]
    for done, fut in enumerate(as_completed(futs), 1):
        _say(progress, f"[{done}/{len(jobs)}] {fut.result()}")


def splat(
    client: Client,
    binary: str,
    inputs: Sequence[str | os.PathLike],
    output: str | os.PathLike,
    flags: Sequence[str] = (),
    progress: Callable[[str], None] | None = print,
    report: str | os.PathLike | None = None,
    **options,
) -> dict:
    """Generates splats from ``inputs`` into ``output`` in tiles on the
    cluster behind ``client``; ``options`` are ``splatray.splat``'s
    (``epsilon``, ``k``, ...) and the tiling's (``tile_points``,
    ``max_memory``), :data:`SPLAT_OPTIONS`; ``flags`` more ``splatray
    splat`` flags; the same for every stage. Returns the merge's report
    (splatray's JSON)."""
    binary = _abs(binary)
    output = _abs(output)
    flags = [*flags, *options_flags(options, SPLAT_OPTIONS, "splat")]
    base = ["splat", *[_abs(p) for p in inputs], "-o", output, *flags]
    out = Path(output)
    plan_json = str(out.with_name(f".{out.name}.plan.json"))
    run_id = uuid.uuid4().hex[:8]
    plan = [*base, "--plan-only", "--report", plan_json]
    _say(progress, _one(client, binary, plan, f"splatray-plan-{run_id}"))
    with open(plan_json, encoding="utf-8") as f:
        n = len(json.load(f)["cores"])
    os.remove(plan_json)
    _fan_out(
        client,
        binary,
        [(f"splatray-tile-{run_id}-{t}", [*base, "--tile", str(t)]) for t in range(n)],
        progress,
    )
    merge_json = str(report) if report else str(out.with_name(f".{out.name}.merge.json"))
    merge = [*base, "--merge-only", "--report", merge_json]
    _say(progress, _one(client, binary, merge, f"splatray-merge-{run_id}"))
    with open(merge_json, encoding="utf-8") as f:
        result = json.load(f)
    if not report:
        os.remove(merge_json)
    return result


def render(
    client: Client,
    binary: str,
    scene: str | os.PathLike,
    output: str | os.PathLike,
    flags: Sequence[str] = (),
    bands: int | None = None,
    progress: Callable[[str], None] | None = print,
    **options,
) -> None:
    """Renders ``scene`` (a scene file or a point cloud) into ``output``
    (.png or .exr) as ``bands`` horizontal bands on the cluster (default:
    one per worker), then stitches them; ``options`` are
    ``splatray.Scene.render``'s (``backend``, ``width``, ``height``,
    ``spp``, ``shading``), ``flags`` more ``splatray render`` flags."""
    binary = _abs(binary)
    flags = [*flags, *options_flags(options, RENDER_OPTIONS, "render")]
    output = _abs(output)
    if bands is None:
        bands = max(1, len(client.scheduler_info()["workers"]))
    out = Path(output)
    run_id = uuid.uuid4().hex[:8]
    parts = [str(out.with_name(f".{out.stem}.band{i:04}-{run_id}{out.suffix}")) for i in range(bands)]
    jobs = [
        (
            f"splatray-band-{run_id}-{i}",
            ["render", _abs(scene), *flags, "--band", f"{i}/{bands}", "-o", parts[i]],
        )
        for i in range(bands)
    ]
    try:
        _fan_out(client, binary, jobs, progress)
        _say(progress, run_binary(binary, ["stitch", *parts, "-o", output]))
    finally:
        for p in parts:
            if os.path.exists(p):
                os.remove(p)
