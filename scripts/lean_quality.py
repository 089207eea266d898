#!/usr/bin/env python3
"""Lean growth (`splat`, the default) against the stages (`splat --no-lean`), measured
against the bunny mesh: for each seed, `splatray sample` draws POINTS
points from scenes/data/bunny-mesh.ply (positions only, as a scan gives
them), both make splats, and `compare --truth` renders each at four views
(the default scene's camera, the whole bunny near, its head, its back;
400x300, a point light) against the mesh. Prints PSNR, mean normal error
and false hits per view, and the mean PSNR difference.

    python3 scripts/lean_quality.py [--bin target/release/splatray]
        [--points 200000] [--seeds 1,11,12] [--work target/lean-quality]
        [--noise SIGMA]

--noise adds isotropic Gaussian noise of SIGMA (the mesh's units; the
bunny's epsilon is 0.0064) to the samples (`sample --noise`).
"""

import argparse
import re
import struct
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MESH = ROOT / "scenes" / "data" / "bunny-mesh.ply"
VIEWS = {
    "far": ("1.5, 1.1, 4.4", "0.0, -0.1, 0.0", 38),
    "near": ("0.8, 0.6, 2.6", "0, 0, 0", 45),
    "head": ("-1.2, 0.6, 1.6", "-0.55, 0.25, 0.2", 30),
    "back": ("-1.5, 0.8, -3.5", "0, 0, 0", 38),
}
SCENE = """background = [0.60, 0.70, 0.85]
[camera]
from = [{frm}]
at = [{at}]
fov = {fov}
width = 400
height = 300
[[model]]
splats = "{splats}"
truth = "{mesh}"
material = {{ kind = "phong", color = [0.85, 0.80, 0.72], specular = 0.15, shininess = 30 }}
[[light]]
kind = "point"
position = [2.5, 4.0, 3.0]
intensity = 28.0
[[light]]
kind = "directional"
direction = [0.3, -0.5, -1.0]
intensity = 0.25
"""
LINE = re.compile(r"octree: coverage \S+, false hits (\S+),.*normal deg mean (\S+) .*PSNR (\S+) dB")


def run(cmd):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"lean_quality: {' '.join(map(str, cmd))} failed:\n{r.stderr}")
    return r


def positions_only(src: Path, dst: Path):
    """`sample`'s binary PLY (x y z as doubles, nx ny nz as floats) as
    x y z alone."""
    data = src.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    n = int(re.search(r"element vertex (\d+)", header).group(1))
    props = re.findall(r"property (\w+) (\w+)", header)
    want = [("double", "x"), ("double", "y"), ("double", "z"), ("float", "nx"), ("float", "ny"), ("float", "nz")]
    if props != want or "binary_little_endian" not in header:
        sys.exit(f"lean_quality: unexpected layout in {src}: {props}")
    size = struct.calcsize("<3d3f")
    body = data[end:end + size * n]
    out = b"".join(body[size * i:size * i + 24] for i in range(n))
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n"
            "property double x\nproperty double y\nproperty double z\nend_header\n" % n)
    dst.write_bytes(head.encode() + out)


def views(binary: str, splats: Path, work: Path):
    got = {}
    for name, (frm, at, fov) in VIEWS.items():
        scene = work / f"view-{name}.toml"
        scene.write_text(SCENE.format(frm=frm, at=at, fov=fov, splats=splats, mesh=MESH))
        r = run([binary, "compare", scene, "--truth"])
        m = LINE.search(r.stderr + r.stdout)
        if not m:
            sys.exit(f"lean_quality: no octree figures from compare {scene}")
        got[name] = (float(m.group(3)), float(m.group(2)), float(m.group(1)))
    return got


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default=str(ROOT / "target/release/splatray"))
    ap.add_argument("--points", type=int, default=200000)
    ap.add_argument("--seeds", default="1,11,12")
    ap.add_argument("--work", default=str(ROOT / "target/lean-quality"))
    ap.add_argument("--noise", type=float, default=0.0, help="sample noise, in the mesh's units")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    diffs = []
    print("| seed | view | stages dB | lean dB | stages normal | lean normal | stages false hits | lean false hits |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for seed in a.seeds.split(","):
        full, cloud = work / f"s{seed}-normals.ply", work / f"s{seed}.ply"
        run([a.bin, "sample", MESH, "-n", a.points, "--seed", seed, "-o", full, "--noise", a.noise])
        positions_only(full, cloud)
        rows = {}
        for kind, extra in (("stages", ["--no-lean"]), ("lean", [])):
            out = work / f"s{seed}-{kind}.ply"
            r = run([a.bin, "splat", cloud, "-o", out, "--holdout", "0"] + extra)
            if kind == "lean":
                note = [line for line in r.stderr.splitlines() if "lean growth" in line]
                print(f"<!-- seed {seed}: {note[0] if note else 'no lean line'} -->")
            rows[kind] = views(a.bin, out, work)
        for name in VIEWS:
            d, l = rows["stages"][name], rows["lean"][name]
            diffs.append(l[0] - d[0])
            print(f"| {seed} | {name} | {d[0]:.2f} | {l[0]:.2f} | {d[1]:.3f}° | {l[1]:.3f}° | "
                  f"{100 * d[2]:.3f} % | {100 * l[2]:.3f} % |", flush=True)
    print(f"\nlean over the stages: mean {sum(diffs) / len(diffs):+.2f} dB, "
          f"from {min(diffs):+.2f} to {max(diffs):+.2f} dB over {len(diffs)} views")


if __name__ == "__main__":
    main()
