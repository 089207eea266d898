"""The cluster of docs/cluster.md, as a new user starts it: a `dask
scheduler` and two `dask worker` processes as separate commands, from a
folder other than the driver's, with only the set-up the document gives
(the environment with the splatray wheel installed; no PYTHONPATH), and
the driver run as `python -m splatray_dask --scheduler ...` without
`--binary`, so the tasks run the wheel's `splatray` command; every one of
those processes runs with the clone's .embree/ and target/ hidden
(`conftest.hiding_clone`): splats and an image byte-identical to the
cargo-built binary on one machine."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from distributed import Client

from conftest import ROOT, hiding_clone, one_machine

BIN = Path(sys.executable).parent  # the environment's bin/, as on PATH


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def cluster(tmp_path):
    """The scheduler's address; its processes run in tmp_path/node."""
    node = tmp_path / "node"
    node.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    address = f"tcp://127.0.0.1:{free_port()}"
    procs = [subprocess.Popen(hiding_clone(["dask", "scheduler", "--host", "127.0.0.1", "--port",
                                            address.rsplit(":", 1)[1], "--no-dashboard"]), cwd=node, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen(hiding_clone(["dask", "worker", address, "--nworkers", "1", "--nthreads",
                                                        "1", "--memory-limit", "0", "--no-dashboard"]),
                                          cwd=node, env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        deadline = time.time() + 60
        while True:
            try:
                with Client(address, timeout=5) as c:
                    c.wait_for_workers(2, timeout=60)
                break
            except OSError:
                assert time.time() < deadline, "the scheduler did not start"
                time.sleep(0.5)
        yield address, node, env
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def driver(node: Path, env: dict, *args: str) -> None:
    r = subprocess.run(hiding_clone([str(BIN / "python"), "-m", "splatray_dask", *args]), cwd=node, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]


def test_a_cluster_started_as_documented_gives_the_one_machine_bytes(cluster, binary, cloud, tmp_path):
    address, node, env = cluster
    local = tmp_path / "local.ply"
    one_machine(binary, ["splat", str(cloud), "-o", str(local), "--tile-points", "30000"])
    out = tmp_path / "out" / "dask.ply"
    out.parent.mkdir()
    driver(node, env, "--scheduler", address,
           "splat", str(cloud), "-o", str(out), "--", "--tile-points", "30000")
    assert out.read_bytes() == local.read_bytes()
    flags = ["--width", "160", "--height", "123", "--spp", "2"]
    scene = ROOT / "scenes" / "bunny.toml"
    one_machine(binary, ["render", str(scene), *flags, "-o", str(tmp_path / "local.png")])
    driver(node, env, "--scheduler", address,
           "render", str(scene), "-o", str(tmp_path / "out" / "dask.png"), "--", *flags)
    assert (tmp_path / "out" / "dask.png").read_bytes() == (tmp_path / "local.png").read_bytes()


def test_the_drivers_options_are_the_packages(client, binary, cloud, tmp_path):
    from splatray_dask import splat

    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    splat(client, binary, [cloud], a, ["--tile-points", "30000", "--epsilon", "0.004"], progress=None)
    splat(client, binary, [cloud], b, tile_points=30000, epsilon=0.004, progress=None)
    assert a.read_bytes() == b.read_bytes()
    # creases=False is --no-creases (creases are on by default).
    c, d = tmp_path / "c.ply", tmp_path / "d.ply"
    splat(client, binary, [cloud], c,
          ["--tile-points", "30000", "--epsilon", "0.004", "--no-creases"], progress=None)
    splat(client, binary, [cloud], d, tile_points=30000, epsilon=0.004, creases=False, progress=None)
    assert c.read_bytes() == d.read_bytes() != a.read_bytes()
    with pytest.raises(TypeError, match="unknown option 'epsilonn'"):
        splat(client, binary, [cloud], b, epsilonn=0.004, progress=None)
