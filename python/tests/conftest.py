"""Fixtures: the release binary, a noisy sampled cloud, Dask LocalClusters."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from distributed import Client, LocalCluster

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def binary() -> str:
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    b = target / "release" / "splatray"
    assert b.exists(), f"{b}: build it first (cargo build --release)"
    return str(b)


@pytest.fixture(scope="session")
def cloud(binary: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """120k noisy points of the bunny without normals (sample's output
    has normals; --noise makes the positions scanner-like)."""
    d = tmp_path_factory.mktemp("cloud")
    p = d / "points.ply"
    subprocess.run(
        [binary, "sample", str(ROOT / "scenes/data/bunny-mesh.ply"), "-n", "120000",
         "--noise", "0.0005", "--seed", "7", "-o", str(p)],
        check=True, capture_output=True,
    )
    return p


def _cluster():
    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        worker_dashboard_address=None,
    )
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="session")
def client():
    """A LocalCluster of 2 worker processes, one thread each."""
    yield from _cluster()


@pytest.fixture()
def fresh_client():
    """A cluster of its own, for a test that kills a worker."""
    yield from _cluster()


def one_machine(binary: str, args: list[str]) -> None:
    r = subprocess.run([binary, *args], capture_output=True, text=True, env=dict(os.environ))
    assert r.returncode == 0, r.stderr


HIDDEN = [d for d in (ROOT / ".embree", ROOT / "target") if d.is_dir()]


def hiding_clone(args: list[str]) -> list[str]:
    """`args` run with the clone's .embree/ and target/ (those it has) hidden:
    in a user and mount namespace (`unshare -rm`) with an empty tmpfs
    mounted over each, so nothing there can be found or loaded."""
    unshare = shutil.which("unshare")
    assert unshare, "no unshare (util-linux) to hide the clone's .embree/ and target/ with"
    script = " && ".join(f'mount -t tmpfs none "${i + 1}"' for i in range(len(HIDDEN)))
    script += f' && shift {len(HIDDEN)} && exec "$@"'
    return [unshare, "-rm", "sh", "-c", script, "sh", *map(str, HIDDEN), *args]
