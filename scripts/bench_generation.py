"""Splat generation benchmark: the whole `splatray splat` at its defaults
(read, outliers, normals, creases, growth, fields, trimming, held-out
check, write) on the clouds users bring, in paired runs against
`--no-creases`, against a previous build (`--baseline BIN`) and, where
Open3D is importable, against Open3D's `estimate_normals(KNN 12)` alone on
the same points. Prints, per cloud, the medians of each command's wall
time, the medians of the pair-by-pair ratios, and points per second of
each generation stage (from the run's own `--report`).

    python/.venv/bin/python scripts/bench_generation.py [--pairs 3]
        [--baseline OLD_SPLATRAY] [--only bunny-200k,survey] [--large] [--stages]

Clouds (made once into --work, default target/bench-generation):
  bunny-200k, bunny-2m  points sampled uniformly from the bundled bunny
                        mesh, positions only (normals estimated);
  survey                `splatray terrain` at its defaults (400k points);
  survey-3.6m           `terrain --size 600 --tiles 4` (with --large);
  noisy-scan            the solids scanned from one station, 1000 x 750
                        rays, range noise of half a spacing and 0.2 %
                        outliers (`sample --scan-from`);
  table-scan            a real laser scan of a table scene, 460,400 points
                        (scenes/data/table_scene_lms400.pcd, as bundled);
  sphere, torus         200k points uniform on a unit sphere and on a torus
                        (radii 1 and 0.35): clouds with no crease, where
                        creases should cost next to nothing.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"bench_generation: {' '.join(map(str, cmd))} failed:\n{r.stderr.strip()}")
    return r


def read_ply_xyz(path):
    """Positions of a binary little-endian PLY vertex element (doubles or
    floats, other float properties skipped)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    n, props = 0, []
    for line in header:
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            n = int(w[2])
        elif w[:1] == ["property"] and n and len(props) < 64:
            props.append((w[2], {"double": "<f8", "float": "<f4"}[w[1]]))
    a = np.frombuffer(data[end:], dtype=np.dtype(props), count=n)
    return np.stack([a["x"], a["y"], a["z"]], 1).astype(np.float64)


def read_pcd_xyz(path):
    """Positions of a binary PCD as `splatray sample` writes it (Open3D
    0.20 reads its 8-byte fields as zeros)."""
    data = Path(path).read_bytes()
    end = data.index(b"DATA binary\n") + len(b"DATA binary\n")
    head = dict(line.split(None, 1) for line in data[:end].decode().splitlines() if " " in line)
    fields, sizes, types = head["FIELDS"].split(), head["SIZE"].split(), head["TYPE"].split()
    kinds = {("F", "8"): "<f8", ("F", "4"): "<f4", ("U", "4"): "<u4", ("U", "1"): "u1"}
    dt = np.dtype([(f, kinds[(t, z)]) for f, t, z in zip(fields, types, sizes)])
    a = np.frombuffer(data[end:], dtype=dt, count=int(head["POINTS"]))
    return np.stack([a["x"], a["y"], a["z"]], 1).astype(np.float64)


def write_ply_xyz(path, xyz):
    head = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(xyz)}\nproperty double x\nproperty double y\n"
        "property double z\nend_header\n"
    ).encode()
    Path(path).write_bytes(head + np.ascontiguousarray(xyz, "<f8").tobytes())


def make_clouds(bin_, work, names):
    """The benchmark's clouds, made once: name -> (input path, points)."""
    work.mkdir(parents=True, exist_ok=True)
    mesh = ROOT / "scenes/data/bunny-mesh.ply"
    out = {}
    for name in names:
        if name.startswith("bunny-"):
            n = {"bunny-200k": 200_000, "bunny-2m": 2_000_000}[name]
            path = work / f"{name}.ply"
            if not path.exists():
                tmp = work / f"{name}-normals.ply"
                run([bin_, "sample", mesh, "-n", str(n), "-o", tmp, "--seed", "42"])
                write_ply_xyz(path, read_ply_xyz(tmp))
                tmp.unlink()
            out[name] = path
        elif name.startswith("survey"):
            big = name == "survey-3.6m"
            d = work / name
            if not (d / "tiles").exists():
                extra = ["--size", "600", "--tiles", "4"] if big else []
                run([bin_, "terrain", "-o", d] + extra)
            out[name] = d / "tiles"
        elif name == "noisy-scan":
            path = work / "noisy-scan.pcd"
            if not path.exists():
                run([bin_, "sample", ROOT / "scenes/data/solids.ply", "--scan-from", "1.9,1.5,2.4",
                     "--scan-at", "0,0.2,0", "--rays", "1000,750", "--range-noise-spacing", "0.5",
                     "--outliers", "0.002", "-o", path, "--seed", "1"])
            out[name] = path
        elif name == "table-scan":
            out[name] = ROOT / "scenes/data/table_scene_lms400.pcd"
        elif name in ("sphere", "torus"):
            path = work / f"{name}.ply"
            if not path.exists():
                write_ply_xyz(path, smooth_cloud(name, 200_000))
            out[name] = path
        else:
            sys.exit(f"bench_generation: no cloud named {name}")
    return out


def smooth_cloud(name, n):
    """n points uniform on a unit sphere, or on a torus (radii 1, 0.35)."""
    rng = np.random.default_rng(3)
    if name == "sphere":
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1)[:, None]
    parts, have = [], 0
    while have < n:
        u, w = rng.uniform(0, 2 * np.pi, (2, 2 * n))
        keep = rng.uniform(0, 1, 2 * n) < (1 + 0.35 * np.cos(w)) / 1.35
        u, w = u[keep], w[keep]
        ring = 1 + 0.35 * np.cos(w)
        parts.append(np.stack([ring * np.cos(u), ring * np.sin(u), 0.35 * np.sin(w)], 1))
        have += len(u)
    return np.concatenate(parts)[:n]


O3D = """
import sys, time, pathlib, numpy as np, open3d as o3d
p = pathlib.Path(sys.argv[1])
if p.suffix == ".ply":
    from bench_generation import read_ply_xyz
    xyz = read_ply_xyz(p)
elif p.suffix == ".pcd" and b"DATA binary_compressed" in p.read_bytes()[:1024]:
    xyz = np.asarray(o3d.io.read_point_cloud(str(p)).points)
elif p.suffix == ".pcd":
    from bench_generation import read_pcd_xyz
    xyz = read_pcd_xyz(p)
else:
    try:
        import laspy
    except ImportError:
        print("skip"); sys.exit(0)
    xyz = np.concatenate([laspy.read(f).xyz for f in sorted(p.glob("*.laz"))])
xyz = xyz[np.isfinite(xyz).all(1)]
xyz = xyz - np.median(xyz, 0)
pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
t = time.perf_counter()
pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(12))
print(time.perf_counter() - t)
"""


def splat_cmd(bin_, cloud, out, report, extra=()):
    return [str(bin_), "splat", str(cloud), "-o", str(out), "--report", str(report), *extra]


def timed(cmd):
    t = time.perf_counter()
    run(cmd)
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=str(ROOT / "target/release/splatray"))
    ap.add_argument("--baseline", help="a previous build's splatray, run in the same pairs")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--only", help="comma-separated cloud names")
    ap.add_argument("--large", action="store_true", help="also the 3.6M-point survey")
    ap.add_argument("--stages", action="store_true",
                    help="also `splat --no-lean` (the stages where lean growth's gate would pass)")
    ap.add_argument("--work", default=str(ROOT / "target/bench-generation"))
    a = ap.parse_args()
    names = ["bunny-200k", "bunny-2m", "survey", "noisy-scan", "table-scan", "sphere"] + (["survey-3.6m"] if a.large else [])
    if a.only:
        names = a.only.split(",")
    clouds = make_clouds(a.bin, Path(a.work), names)
    try:
        import open3d  # noqa: F401
        have_o3d = True
    except ImportError:
        have_o3d = False
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, cloud in clouds.items():
            cmds = {"splat": splat_cmd(a.bin, cloud, tmp / "a.ply", tmp / "a.json"),
                    "no-creases": splat_cmd(a.bin, cloud, tmp / "b.ply", tmp / "b.json", ["--no-creases"])}
            if a.baseline:
                cmds["baseline"] = splat_cmd(a.baseline, cloud, tmp / "c.ply", tmp / "c.json")
            if a.stages:
                cmds["stages"] = splat_cmd(a.bin, cloud, tmp / "d.ply", tmp / "d.json", ["--no-lean"])
            times = {k: [] for k in cmds}
            o3d = have_o3d
            for _ in range(a.pairs):
                for k, c in cmds.items():
                    times[k].append(timed(c))
                if o3d:
                    r = run([sys.executable, "-c", O3D, str(cloud)],
                            env={**os.environ, "PYTHONPATH": str(ROOT / "scripts")})
                    out = r.stdout.strip().splitlines()[-1]
                    o3d = out != "skip"
                    if o3d:
                        times.setdefault("open3d", []).append(float(out))
            rep = json.loads((tmp / "a.json").read_text())
            n = rep.get("input_points") or rep.get("points")
            s = rep["seconds"]
            med = {k: statistics.median(v) for k, v in times.items()}
            ratio = {k: statistics.median(x / y for x, y in zip(times["splat"], v))
                     for k, v in times.items() if k != "splat"}
            if "tiles" in rep:  # a tiled run: each tile's own gate
                lean = sum(bool(t.get("lean")) for t in rep["tiles"])
                said = f"used in {lean} of {len(rep['tiles'])} tiles"
            else:
                said = "used" if (rep.get("lean") or {}).get("used") else "refused by its gate"
            print(f"{name}: lean growth {said}", flush=True)
            # A stage that found nothing to do (trimming without a viewpoint,
            # colours of a cloud without them) takes microseconds: no rate.
            stages = {k: v for k, v in s.items() if k not in ("total",) and v >= 1e-3}
            if rep.get("heldout_seconds"):
                stages["held-out"] = rep["heldout_seconds"]
            rows.append((name, n, med, ratio, stages, n))
            print(f"{name}: {n} points, {rep['splats']} splats; median wall "
                  + ", ".join(f"{k} {v:.2f} s" for k, v in med.items())
                  + "; ratios splat/" + ", splat/".join(f"{k} {v:.2f}" for k, v in ratio.items())
                  + "; points/s by stage " + ", ".join(f"{k} {n / v / 1e3:.0f}k" for k, v in stages.items()),
                  flush=True)
    print()
    cols = ["splat"] + [k for k in ("no-creases", "baseline", "stages", "open3d") if any(k in r[2] for r in rows)]
    print("| cloud | points | " + " | ".join(f"{c} s" for c in cols) + " | "
          + " | ".join(f"splat / {c}" for c in cols[1:]) + " |")
    print("|---|---:|" + "---:|" * (2 * len(cols) - 1))
    for name, pts, med, ratio, _, _ in rows:
        cells = [f"{med[c]:.2f}" if c in med else "–" for c in cols]
        rcells = [f"{ratio[c]:.2f}" if c in ratio else "–" for c in cols[1:]]
        print(f"| {name} | {pts:,} | " + " | ".join(cells) + " | " + " | ".join(rcells) + " |")


if __name__ == "__main__":
    main()
