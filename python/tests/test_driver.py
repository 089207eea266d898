"""The Dask driver gives the bytes of a one-machine run: splats in tiles,
an image in bands, and splats again when a worker dies mid-run."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from conftest import ROOT, one_machine
from splatray_dask import SplatrayError, render, splat

FLAGS = ["--tile-points", "30000"]


def test_tiles_on_a_cluster_give_the_one_machine_bytes(client, binary, cloud, tmp_path):
    local = tmp_path / "local.ply"
    one_machine(binary, ["splat", str(cloud), "-o", str(local), *FLAGS])
    out = tmp_path / "dask.ply"
    report = splat(client, binary, [cloud], out, FLAGS, progress=None)
    assert len(report["tiles"]) >= 6
    assert report["splats"] > 10_000
    assert out.read_bytes() == local.read_bytes()
    # The work folder and the driver's own files are gone.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dask.ply", "local.ply"]


def test_bands_on_a_cluster_give_the_one_machine_image(client, binary, tmp_path):
    scene = ROOT / "scenes" / "bunny.toml"
    flags = ["--width", "160", "--height", "123", "--spp", "2"]
    local = tmp_path / "local.png"
    one_machine(binary, ["render", str(scene), *flags, "-o", str(local)])
    out = tmp_path / "dask.png"
    # Three bands on two workers: rows split unevenly (123 = 41 * 3).
    render(client, binary, scene, out, flags, bands=3, progress=None)
    assert out.read_bytes() == local.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dask.png", "local.png"]


def test_a_failing_task_is_one_line(client, binary, tmp_path):
    with pytest.raises(SplatrayError) as e:
        splat(client, binary, [tmp_path / "missing.ply"], tmp_path / "o.ply", FLAGS, progress=None)
    assert "missing.ply" in str(e.value) and "\n" not in str(e.value)
    assert not (tmp_path / "o.ply").exists()


def _wrapper(tmp_path: Path, binary: str) -> tuple[Path, Path]:
    """A stand-in for the binary whose first tile task announces itself
    (its pid in ``signals/started``) and then waits, without end, for the
    kill: that task cannot finish before its worker dies. Every other call
    (the plan, the merge, the rerun of the killed tile) runs the binary."""
    signals = tmp_path / "signals"
    signals.mkdir()
    script = tmp_path / "splatray-wrapper"
    script.write_text(
        f"""#!/bin/sh
case " $* " in
*" --tile "*)
    if mkdir "{signals}/claimed" 2>/dev/null; then
        echo $$ > "{signals}/started.tmp" && mv "{signals}/started.tmp" "{signals}/started"
        sleep 600
        echo $$ > "{signals}/not-killed"
        exit 1
    fi ;;
esac
exec "{binary}" "$@"
"""
    )
    script.chmod(0o755)
    return script, signals


def _parent(pid: int) -> int:
    """The parent of ``pid``, or -1 once it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="utf-8") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except FileNotFoundError:
        return -1


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="utf-8") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_worker_killed_mid_run_changes_nothing(fresh_client, binary, cloud, tmp_path):
    client = fresh_client
    local = tmp_path / "local.ply"
    one_machine(binary, ["splat", str(cloud), "-o", str(local), *FLAGS])
    wrapper, signals = _wrapper(tmp_path, binary)
    pids = client.run(os.getpid)
    killed: list[tuple[str, int]] = []
    problems: list[str] = []

    def kill_the_worker_running_the_waiting_tile() -> None:
        # The tile announces itself once it runs; it then waits for the
        # kill, so the kill lands mid-task, by construction.
        deadline = time.time() + 120
        started = signals / "started"
        while not started.exists():
            if time.time() > deadline:
                problems.append("no tile task started within 120 s")
                return
            time.sleep(0.02)
        task = int(started.read_text())
        worker = next((w for w, p in pids.items() if p == _parent(task)), None)
        if worker is None or not _alive(task):
            problems.append(f"the waiting tile (pid {task}) is not a running child of a worker")
            return
        os.kill(pids[worker], signal.SIGKILL)
        killed.append((worker, task))
        # The task dies with its worker (the driver's PR_SET_PDEATHSIG).
        end = time.time() + 10
        while _alive(task) and time.time() < end:
            time.sleep(0.02)
        if _alive(task):
            problems.append(f"the tile's process {task} outlived its killed worker")

    killer = threading.Thread(target=kill_the_worker_running_the_waiting_tile)
    killer.start()
    out = tmp_path / "dask.ply"
    report = splat(client, str(wrapper), [cloud], out, FLAGS, progress=None)
    killer.join()
    assert not problems, problems
    assert len(killed) == 1, "no worker was killed mid-task"
    # Killed while running: it never reached its end.
    assert not (signals / "not-killed").exists()
    assert len(report["tiles"]) >= 6
    assert out.read_bytes() == local.read_bytes()
