"""scan_check and sweep from Python against the command line's reports on
the same small inputs: the same dicts as scan-check's JSON (lines of sight
and the photo check), the same rows as sweep's CSV; every figure but the
timings, which no two runs share."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest

import splatray
from conftest import ROOT

MESH = ROOT / "scenes/data/bunny-mesh.ply"


def run(binary: str, *args: str) -> None:
    r = subprocess.run([binary, *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def untimed(value):
    """`value` without its timings (keys ending in `seconds` or `_s`)."""
    if isinstance(value, dict):
        return {k: untimed(v) for k, v in value.items()
                if not (k.endswith("seconds") or k.endswith("_s"))}
    if isinstance(value, list):
        return [untimed(v) for v in value]
    return value


@pytest.fixture(scope="module")
def scans(binary: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 80x60 scan of the bunny (scan.pcd) and an organised, textured
    capture of it (photo.pcd)."""
    d = tmp_path_factory.mktemp("scans")
    scan = ["--scan-from", "0.3,0.2,0.4", "--rays", "80,60"]
    run(binary, "sample", str(MESH), *scan, "--range-noise", "0.0002", "-o", str(d / "scan.pcd"))
    run(binary, "sample", str(MESH), *scan, "--organised", "optical", "--texture", "0.02",
        "-o", str(d / "photo.pcd"))
    return d


@pytest.mark.parametrize("photo", [False, True])
def test_scan_check_is_the_cli_report(binary, scans, tmp_path, photo):
    name = "photo.pcd" if photo else "scan.pcd"
    args = ["--holdout", "0.2", "--seed", "5", "--epsilon", "0.004"] + (["--photo"] if photo else [])
    run(binary, "scan-check", str(scans / name), *args, "--report", str(tmp_path / "r.json"))
    want = json.loads((tmp_path / "r.json").read_text())
    stages = []
    got = splatray.scan_check(scans / name, holdout=0.2, seed=5, epsilon=0.004, photo=photo,
                              progress=lambda s, f: stages.append(s))
    assert untimed(got) == untimed(want)
    # The report says something: points were held out and checked.
    assert got["held_out"] > 100, got["held_out"]
    if not photo:
        assert got["rays"] == got["consistent"] + got["early"] + got["late"] + got["miss"]


def test_scan_check_errors_are_the_cli_messages(binary, scans, tmp_path):
    with pytest.raises(splatray.SplatrayError, match="viewpoint"):
        splatray.scan_check(scans / "scan.pcd", no_viewpoint=True)
    with pytest.raises(splatray.SplatrayError, match="organised"):
        splatray.scan_check(scans / "scan.pcd", photo=True)
    with pytest.raises(splatray.SplatrayError, match="missing.pcd"):
        splatray.scan_check(tmp_path / "missing.pcd")


def test_sweep_rows_are_the_cli_csv(binary, tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        '[camera]\nfrom = [1.5, 1.1, 4.4]\nat = [0.0, -0.1, 0.0]\nfov = 34\n'
        f'[[model]]\nmesh = "{MESH.as_posix()}"\nsamples = 3000\nseed = 3\n'
        '[[light]]\nkind = "point"\nposition = [2.0, 4.0, 3.0]\nintensity = 20.0\n'
    )
    opts = dict(width=32, height=24, steps=5, eps_coarse=0.05, eps_fine=0.02)
    run(binary, "sweep", str(scene), *[a for k, v in opts.items()
                                         for a in (f"--{k.replace('_', '-')}", str(v))],
        "--csv", str(tmp_path / "s.csv"))
    with open(tmp_path / "s.csv", newline="") as f:
        want = list(csv.DictReader(f))
    got = splatray.sweep(scene, **opts)
    # Five steps in three modes, then the mesh row (issue 57).
    assert len(got) == len(want) == 5 * 3 + 1
    mesh, want_mesh = got.pop(), want.pop()
    names = [b["name"] for b in got[0]["backends"]]
    assert names == splatray.BACKENDS[: len(names)] and len(names) >= 2
    for g, w in zip(got, want):
        ref = g["backends"][0]["errors"]
        assert [g["step"], g["shading"], g["splats"], g["scene_splats"]] == \
            [int(w["step"]), w["shading"], int(w["splats"]), int(w["scene_splats"])]
        assert g["epsilon_rel"] == pytest.approx(float(w["epsilon"]), rel=1e-6)
        for k in ["coverage", "false_hits", "depth_rel_p50", "depth_rel_p99",
                  "normal_deg_mean", "normal_deg_p99"]:
            assert ref[k] == float(w[k]), k
        psnr = ref["image_psnr_db"]
        assert (psnr is None and w["psnr_db"] == "inf") or psnr == float(w["psnr_db"])
        assert g["backends_identical"] == (w["backends_identical"] == "true")
        for b in g["backends"][1:]:
            assert b["errors"]["normal_deg_mean"] == float(w[f"{b['name']}_normal_deg_mean"])
    # Smaller epsilon, more splats.
    assert got[-1]["splats"] > got[0]["splats"]
    # The mesh row: the bunny's triangles on every backend, shaded smooth as
    # the exact surface is: its measured error near zero, a measured speed.
    assert mesh["shading"] == want_mesh["shading"] == "mesh"
    assert mesh["triangles"] == int(want_mesh["triangles"]) == 69666
    assert mesh["splats"] == mesh["scene_splats"] == 0
    assert mesh["backends_identical"] and want_mesh["backends_identical"] == "true"
    assert [b["name"] for b in mesh["backends"]] == names
    for b in mesh["backends"]:
        assert b["render_s"] > 0 and b["mrays_per_s"] > 0 and b["memory_bytes"] > 69666 * 36
        # The CSV's figures, and near zero: the same surface and normals,
        # only silhouette pixels traced apart (flat faces: about 1.2 deg).
        assert b["errors"]["normal_deg_mean"] == float(want_mesh[
            "normal_deg_mean" if b["name"] == names[0] else f"{b['name']}_normal_deg_mean"])
        assert b["errors"]["normal_deg_mean"] < 0.01  # measured 0.0001 at 32x24
        assert b["errors"]["coverage"] > 0.99


def test_sweep_refuses_bad_options_before_work(tmp_path):
    with pytest.raises(ValueError, match="--steps 2"):
        splatray.sweep(tmp_path / "none.toml", steps=2)
    with pytest.raises(splatray.SplatrayError, match="none.toml"):
        splatray.sweep(tmp_path / "none.toml", steps=5)
