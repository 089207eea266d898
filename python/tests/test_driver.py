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


def test_a_worker_killed_mid_run_changes_nothing(fresh_client, binary, cloud, tmp_path):
    client = fresh_client
    local = tmp_path / "local.ply"
    one_machine(binary, ["splat", str(cloud), "-o", str(local), *FLAGS])
    pids = client.run(os.getpid)
    killed: list[str] = []

    def kill_a_worker_running_a_tile() -> None:
        deadline = time.time() + 120
        while time.time() < deadline and not killed:
            for worker, keys in client.processing().items():
                if any("splatray-tile-" in str(k) for k in keys):
                    # Let the tile's process start its work, then kill the
                    # worker (its splatray process dies with it).
                    time.sleep(0.3)
                    os.kill(pids[worker], signal.SIGKILL)
                    killed.append(worker)
                    return
            time.sleep(0.02)

    killer = threading.Thread(target=kill_a_worker_running_a_tile)
    killer.start()
    out = tmp_path / "dask.ply"
    report = splat(client, binary, [cloud], out, FLAGS, progress=None)
    killer.join()
    assert killed, "no worker was killed: the run ended first"
    assert len(report["tiles"]) >= 6
    assert out.read_bytes() == local.read_bytes()
