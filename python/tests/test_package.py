"""The Python package against the command line: numpy -> splats -> render
gives the CLI's bytes; cast_rays gives, ray for ray, the hits the CLI's
renders resolve (its depth, splat-id and normal AOVs), on both backends;
bad arrays raise before any work; the GIL is released while it works."""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import splatray
from conftest import ROOT

CAMERA = {"from": [0.4, 0.5, 3.2], "at": [0.0, 0.1, 0.0], "fov": 30, "width": 64, "height": 48}
SIZE = ["--width", "64", "--height", "48"]


def run(binary: str, *args: str) -> None:
    r = subprocess.run([binary, *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def points(binary: str, tmp_path_factory: pytest.TempPathFactory) -> np.ndarray:
    """12k noisy bunny points as float64 numpy (written as XYZ text with
    every digit, so the CLI reads the same numbers)."""
    d = tmp_path_factory.mktemp("pts")
    ply = d / "s.ply"
    run(binary, "sample", str(ROOT / "scenes/data/bunny-mesh.ply"), "-n", "12000",
        "--noise", "0.0005", "--seed", "3", "-o", str(ply))
    return splatray.read_points(ply).positions


@pytest.fixture(scope="module")
def cli(binary: str, points: np.ndarray, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The CLI's splats of `points` (cli.ply) and a scene file over them."""
    d = tmp_path_factory.mktemp("cli")
    np.savetxt(d / "pts.xyz", points, fmt="%.17g")
    run(binary, "splat", str(d / "pts.xyz"), "-o", str(d / "cli.ply"), "--epsilon", "0.004", "--holdout", "0")
    c = CAMERA
    (d / "scene.toml").write_text(
        f"[camera]\nfrom = {c['from']}\nat = {c['at']}\nfov = {c['fov']}\nwidth = 64\nheight = 48\n"
        '[[model]]\nsplats = "cli.ply"\n'
        'material = { kind = "phong", color = [0.8, 0.7, 0.6], specular = 0.2, shininess = 20 }\n'
        '[[light]]\nkind = "point"\nposition = [2.0, 3.0, 4.0]\nintensity = 20.0\n'
    )
    return d


def test_numpy_splats_and_render_are_the_cli_bytes(binary, points, cli, tmp_path):
    sp = splatray.splat(points, epsilon=0.004)
    assert len(sp) > 100 and sp.report["generation"]["splats"] == len(sp)
    sp.save(tmp_path / "py.ply")
    assert (tmp_path / "py.ply").read_bytes() == (cli / "cli.ply").read_bytes()
    run(binary, "render", str(cli / "scene.toml"), "-o", str(tmp_path / "cli.png"))
    scene = splatray.Scene(
        camera=CAMERA,
        models=[{"splats": sp, "material": {"kind": "phong", "color": [0.8, 0.7, 0.6], "specular": 0.2, "shininess": 20}}],
        lights=[{"kind": "point", "position": [2.0, 3.0, 4.0], "intensity": 20.0}],
    )
    img = scene.render()
    assert img.rgb.shape == (48, 64, 3) and img.rgb.dtype == np.float32
    img.save(tmp_path / "py.png")
    assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    # The same from the scene file, and the notebook's PNG is an image.
    splatray.Scene.from_toml(cli / "scene.toml").render().save(tmp_path / "toml.png")
    assert (tmp_path / "toml.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    assert img._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"


def test_lean_growth_is_the_cli_lean_bytes(binary, points, tmp_path):
    """Lean growth by default: on a dense clean sphere its gate passes and
    the file is the CLI's bytes; lean=False is --no-lean, the stages; on the
    noisy bunny sample it refuses, says why, and the splats are the
    stages'."""
    n = 150_000
    i = np.arange(n) + 0.5
    y = 1.0 - 2.0 * i / n
    t = np.pi * (3.0 - np.sqrt(5.0)) * np.arange(n)
    r = np.sqrt(1.0 - y * y)
    sphere = np.c_[r * np.cos(t), y, r * np.sin(t)]
    lean = splatray.splat(sphere)
    assert lean.report["generation"]["lean"]["used"] is True
    np.savetxt(tmp_path / "sphere.xyz", sphere, fmt="%.17g")
    xyz = str(tmp_path / "sphere.xyz")
    run(binary, "splat", xyz, "--holdout", "0", "-o", str(tmp_path / "cli.ply"))
    lean.save(tmp_path / "py.ply")
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()
    stages = splatray.splat(sphere, lean=False)
    assert stages.report["generation"]["lean"] is None
    run(binary, "splat", xyz, "--no-lean", "--holdout", "0", "-o", str(tmp_path / "cli-stages.ply"))
    stages.save(tmp_path / "py-stages.ply")
    assert (tmp_path / "py-stages.ply").read_bytes() == (tmp_path / "cli-stages.ply").read_bytes()
    assert len(stages) != len(lean)
    refused = splatray.splat(points, epsilon=0.004)
    report = refused.report["generation"]["lean"]
    assert report["used"] is False and "scatter" in report["refused"], report
    assert np.array_equal(refused.centers, splatray.splat(points, epsilon=0.004, lean=False).centers)


def test_creases_give_clip_lines_and_the_cli_creases_bytes(binary, tmp_path):
    """A gable roof (two faces meeting at a ridge, 53 degrees apart, with
    free borders all round): with creases=True its splats at the ridge and
    the borders carry clip lines, and the file is --creases' bytes; the
    default is the same (a roof is not sampled along scan lines), and
    creases=False gives none."""
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1.0, 1.0, (8000, 2))
    roof = np.c_[xy, 0.5 - 0.5 * np.abs(xy[:, 0])]
    on = splatray.splat(roof, creases=True)
    off = splatray.splat(roof, creases=False)
    default = splatray.splat(roof)
    lines_on, lines_off = on.clip_lines, off.clip_lines
    assert lines_on.shape == (len(on), 6) and lines_on.dtype == np.float32
    # Measured: 216 of 271 splats clipped (the ridge and the four free
    # borders of the square).
    assert np.any(lines_on != 0.0, axis=1).sum() > 0.7 * len(on)
    assert not np.any(lines_off)
    assert np.array_equal(default.clip_lines, lines_on)
    np.savetxt(tmp_path / "roof.xyz", roof, fmt="%.17g")
    run(binary, "splat", str(tmp_path / "roof.xyz"), "--creases", "--holdout", "0",
        "-o", str(tmp_path / "cli.ply"))
    on.save(tmp_path / "py.ply")
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()


@pytest.mark.parametrize("backend", ["octree", "embree"])
def test_cast_rays_are_the_cli_renders_hits(binary, cli, tmp_path, backend):
    out = tmp_path / "r.png"
    run(binary, "render", str(cli / "scene.toml"), "--backend", backend, "--aov", "depth,splat,normal", "-o", str(out))
    depth = splatray.read_image(tmp_path / "r.depth.exr")[..., 0].ravel()
    ids = splatray.read_image(tmp_path / "r.splat.exr")[..., 0].ravel()
    normal = splatray.read_image(tmp_path / "r.normal.exr").reshape(-1, 3)
    scene = splatray.Scene.from_toml(cli / "scene.toml")
    rays = scene.camera_rays()
    assert rays.shape == (64 * 48, 6)
    hit = ids >= 0
    assert 0.2 < hit.mean() < 0.9, hit.mean()  # the bunny and the background
    length = np.linalg.norm(rays[:, 3:].astype(np.float32), axis=1)
    # The scene's own splats resolve bit for bit as its render; the splat
    # file's alone, re-centred on their own, round a little differently
    # (measured: normals within 3.0e-6, distances within 3.6e-7 relative)
    # but meet the same splats.
    whole = scene.splat_scene(backend)
    alone = splatray.SplatScene(splatray.Splats.load(cli / "cli.ply"), backend)
    for ss, tol in ((whole, 0.0), (alone, 1e-5)):
        assert ss.backend == backend
        r = ss.cast_rays(rays)
        got = r["splat_ids"]
        assert np.array_equal(got == splatray.INVALID_ID, ~hit)
        assert np.array_equal(got[hit].astype(np.float64), ids[hit].astype(np.float64))
        np.testing.assert_allclose(r["normals"], normal, rtol=0, atol=tol)
        assert np.all(np.isinf(r["t_hit"][~hit]))
        # t in units of the direction's length; the AOV's is a distance.
        np.testing.assert_allclose(r["t_hit"][hit] * length[hit], depth[hit], rtol=max(tol, 1e-6))
        # The distance alone when the rest is not asked for: the same bits.
        t_only = ss.cast_rays(rays, splat_ids=False, normals=False)
        assert list(t_only) == ["t_hit"]
        assert np.array_equal(t_only["t_hit"].view(np.uint32), r["t_hit"].view(np.uint32))
    # Through the surface and out: a ray through the bunny's middle meets
    # an even number of surfaces, one that misses none.
    ss = scene.splat_scene(backend)
    centre = rays[(24 * 64 + 32):(24 * 64 + 33)]
    assert ss.count_intersections(centre)[0] % 2 == 0 and ss.count_intersections(centre)[0] >= 2
    assert ss.occluded(centre).tolist() == [True]
    assert ss.count_intersections(rays[~hit][:5]).tolist() == [0] * 5
    assert not ss.occluded(rays[~hit][:5]).any()


@pytest.mark.parametrize(
    "bad, error, says",
    [
        (np.zeros((10, 2)), ValueError, "shape (N, 3)"),
        (np.zeros(30), TypeError, "shape (30,)"),
        (np.zeros((10, 3), dtype=np.int64), TypeError, "int64"),
        (np.zeros((0, 3)), ValueError, "empty"),
        (np.array([[0.0, 0.0, 0.0], [np.nan, 1.0, 2.0]]), ValueError, "row 1"),
        ([[0.0, 0.0, 0.0]], TypeError, "list"),
    ],
)
def test_a_bad_points_array_raises_before_any_work(bad, error, says):
    with pytest.raises(error) as e:
        splatray.splat(bad)
    assert says in str(e.value) and "\n" not in str(e.value)


def test_bad_rays_and_inputs_raise(points):
    ss = splatray.SplatScene(splatray.splat(points, epsilon=0.01), "octree")
    ok = np.array([[0.0, 0.0, 3.0, 0.0, 0.0, -1.0]], dtype=np.float32)
    assert ss.cast_rays(ok)["splat_ids"].shape == (1,)
    assert ss.cast_rays(np.zeros((0, 6), np.float32))["t_hit"].shape == (0,)
    for bad, error in [
        (ok[:, :5], ValueError),
        (ok.astype(np.int32), TypeError),
        (np.array([[0, 0, 3, 0, 0, 0]], np.float32), ValueError),
        (np.array([[0, 0, np.inf, 0, 0, -1]], np.float32), ValueError),
    ]:
        with pytest.raises(error):
            ss.cast_rays(bad)
    # Of several bad rows (converted in parallel), the first is named.
    many = np.repeat(ok, 5000, axis=0)
    many[3000, 5] = 0.0
    many[4000, 0] = np.nan
    many[700, 3:] = 0.0
    for call in (ss.cast_rays, ss.occluded):
        with pytest.raises(ValueError) as e:
            call(many)
        assert str(e.value) == "rays: row 700 has a zero (or too small or large) direction"
    with pytest.raises(ValueError, match="normals has 2 rows"):
        splatray.splat(points, normals=np.ones((2, 3)))
    # The library's own errors: one line, naming what is wrong.
    with pytest.raises(splatray.SplatrayError, match="one line"):
        splatray.splat(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    with pytest.raises(splatray.SplatrayError, match="missing.ply"):
        splatray.read_points("missing.ply")
    with pytest.raises(ValueError, match="unknown AOV"):
        splatray.Scene(camera=CAMERA, models=[{"splats": splatray.splat(points, epsilon=0.01)}]).render(aov=["nope"])
    with pytest.raises(splatray.SplatrayError, match="colour"):
        splatray.Scene(camera=CAMERA, models=[{"shape": {"kind": "sphere", "radius": 1, "splats": 100}, "colour": 1}])


def test_the_gil_is_released_during_a_render(points):
    sp = splatray.splat(points, epsilon=0.004)
    scene = splatray.Scene(camera=CAMERA, models=[{"splats": sp}],
                           lights=[{"kind": "sphere", "position": [2.0, 3.0, 4.0], "radius": 0.5, "samples": 16}])
    ticks = [0]
    done = threading.Event()

    def count() -> None:
        while not done.is_set():
            ticks[0] += 1

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.1)
    start = time.perf_counter()
    before = ticks[0]
    rate = before / 0.1  # the counter's pace alone (roughly)
    stages = []
    img = scene.render(width=160, height=120, spp=4, progress=lambda s, f: stages.append(s))
    seconds = time.perf_counter() - start
    during = ticks[0] - before
    done.set()
    t.join()
    assert img.shape == (120, 160) and "render" in stages
    # Held, the GIL would let the counter run at most a switch interval
    # (5 ms) of the render; released, it runs alongside the render's
    # threads on the shared cores.
    assert seconds > 0.1, seconds
    assert during > 0.1 * rate * seconds, (during, rate, seconds)


def test_compare_reports_what_the_cli_reports(binary, cli, tmp_path):
    run(binary, "compare", str(cli / "scene.toml"), "--width", "32", "--height", "24",
        "--report", str(tmp_path / "r.json"))
    import json

    want = json.loads((tmp_path / "r.json").read_text())
    got = splatray.Scene.from_toml(cli / "scene.toml").compare(width=32, height=24)
    assert [b["name"] for b in got["backends"]] == [b["name"] for b in want["backends"]]
    assert got["splats"] == want["splats"] and got["rays"] == want["rays"] == 32 * 24
    # The agreement is measured from the frames, the same in both runs (the
    # timings are not).
    for g, w in zip(got["backends"][1:], want["backends"][1:]):
        assert g["agreement"] == w["agreement"]
        assert g["agreement"]["same_splat"] == 1.0


# A square of two triangles beside the bunny (which spans about ±1), in the
# plane z = 0, its winding facing +z.
QUAD_V = np.array([[3.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0, 2.0, 0.0], [3.0, 2.0, 0.0]])
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def test_cast_rays_meet_triangles_beside_splats(points):
    """Issue 57: triangles given as arrays beside the splats are cast as the
    renderer traces them, on every backend alike; their ids follow the
    splats' (face i is `first_triangle + i`)."""
    sp = splatray.splat(points, epsilon=0.01)
    c = points.mean(axis=0)
    rays = np.array([
        [4.5, 0.5, 2.0, 0.0, 0.0, -2.0],   # face 0 (below the diagonal), t = 1
        [3.5, 1.5, 1.0, 0.0, 0.0, -1.0],   # face 1, t = 1
        [4.0, 1.0, 3.0, 0.0, 0.0, -3.0],   # the shared edge: one face, t = 1
        [c[0], c[1], c[2] + 5.0, 0.0, 0.0, -1.0],  # the bunny: a splat
        [10.0, 10.0, 10.0, 1.0, 0.0, 0.0],  # nothing
    ])
    got = {}
    for backend in splatray.BACKENDS:
        ss = splatray.SplatScene(sp, backend, vertices=QUAD_V, faces=QUAD_F)
        first = ss.first_triangle
        assert first == len(sp) and ss.triangles == 2
        r = ss.cast_rays(rays)
        ids, t = r["splat_ids"], r["t_hit"]
        assert ids[0] == first and ids[1] == first + 1 and ids[2] in (first, first + 1)
        np.testing.assert_allclose(t[:3], 1.0, rtol=1e-6)
        np.testing.assert_allclose(r["normals"][:3], [[0, 0, 1]] * 3, atol=1e-6)
        assert ids[3] < first and np.isfinite(t[3])
        assert ids[4] == splatray.INVALID_ID and np.isinf(t[4])
        # A shadow ray stops at the triangle, not before it.
        assert ss.occluded(rays[:1], tfar=1.1).tolist() == [True]
        assert ss.occluded(rays[:1], tfar=0.9).tolist() == [False]
        assert not ss.occluded(rays[4:]).any()
        # The square is one surface, from either side.
        assert ss.count_intersections(rays[:1]).tolist() == [1]
        assert ss.count_intersections(rays[:1] * [1, 1, -1, 1, 1, -1]).tolist() == [1]
        got[backend] = r
    a = got[splatray.BACKENDS[0]]
    for n, b in got.items():
        assert np.array_equal(a["t_hit"].view(np.uint32), b["t_hit"].view(np.uint32)), n
        assert np.array_equal(a["splat_ids"], b["splat_ids"]), n
        assert np.array_equal(a["normals"], b["normals"]), n


def test_a_scene_files_triangles_are_cast_as_rendered(points, tmp_path):
    """A scene's `triangles` model: `splat_scene` casts its camera rays to
    the ids its render's splat AOV holds, triangles and splats, on every
    backend; the same faces as the arrays give."""
    (tmp_path / "quad.obj").write_text("v 3 0 0\nv 5 0 0\nv 5 2 0\nv 3 2 0\nf 1 2 3\nf 1 3 4\n")
    sp = splatray.splat(points, epsilon=0.01)
    camera = {"from": [2.0, 1.0, 6.0], "at": [2.0, 0.5, 0.0], "fov": 60, "width": 48, "height": 32}
    scene = splatray.Scene(camera=camera, models=[{"splats": sp}, {"triangles": str(tmp_path / "quad.obj")}],
                           lights=[{"kind": "point", "position": [2.0, 3.0, 4.0], "intensity": 20.0}])
    rays = scene.camera_rays()
    ids = {}
    for backend in splatray.BACKENDS:
        ss = scene.splat_scene(backend)
        assert (ss.first_triangle, ss.triangles) == (len(sp), 2)
        r = ss.cast_rays(rays)
        aov = scene.render(backend=backend, aov=["splat"]).aov["splat"].ravel()
        assert np.array_equal(r["splat_ids"], aov)
        ids[backend] = r["splat_ids"]
        on_tri = r["splat_ids"] != splatray.INVALID_ID
        on_tri &= r["splat_ids"] >= len(sp)
        on_splat = r["splat_ids"] < len(sp)
        # Measured: 81 triangle and 61 splat pixels of 1,536.
        assert on_tri.sum() >= 70 and on_splat.sum() >= 50, (on_tri.sum(), on_splat.sum())
        # The arrays' faces are the file's: the same ids at the same rays.
        direct = splatray.SplatScene(sp, backend, vertices=QUAD_V, faces=QUAD_F).cast_rays(rays)
        assert np.array_equal(direct["splat_ids"][on_tri], r["splat_ids"][on_tri])
    for n in splatray.BACKENDS:
        assert np.array_equal(ids[splatray.BACKENDS[0]], ids[n]), n


@pytest.mark.parametrize(
    "arrays, error, says",
    [
        (dict(vertices=QUAD_V[:, :2], faces=QUAD_F), ValueError, "vertices must be"),
        (dict(vertices=QUAD_V, faces=QUAD_F[:, :2]), ValueError, "faces must be"),
        (dict(vertices=QUAD_V, faces=QUAD_F.astype(np.float64)), TypeError, "faces must be an int32"),
        (dict(vertices=QUAD_V, faces=[[0, 1, 2]]), TypeError, "list"),
        (dict(vertices=QUAD_V, faces=np.array([[0, 1, 4]])), ValueError, "faces: row 0 has index 4, not in 0..4"),
        (dict(vertices=QUAD_V, faces=np.array([[0, 1, 2], [0, -1, 3]])), ValueError, "faces: row 1 has index -1"),
        (dict(vertices=QUAD_V, faces=np.array([[0, 1, 2**40]], np.uint64)), ValueError, "not in 0..4"),
        (dict(vertices=np.vstack([QUAD_V, [[np.nan, 0, 0]]]), faces=QUAD_F), ValueError, "vertices: row 4 holds a NaN"),
        (dict(vertices=np.vstack([QUAD_V, [[np.inf, 0, 0]]]), faces=QUAD_F), ValueError, "vertices: row 4"),
        (dict(vertices=QUAD_V, faces=np.array([[0, 1, 2], [0, 2, 2]])), ValueError, "faces: row 1 is degenerate"),
        (dict(vertices=np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), faces=np.array([[0, 1, 2]])),
         ValueError, "faces: row 0 spans no area"),
        (dict(vertices=QUAD_V, faces=np.zeros((0, 3), np.int64)), ValueError, "faces is empty"),
        (dict(vertices=QUAD_V), ValueError, "both `vertices` and `faces`"),
    ],
)
def test_bad_triangle_arrays_raise(points, arrays, error, says):
    sp = splatray.splat(points, epsilon=0.01)
    for backend in splatray.BACKENDS:
        with pytest.raises(error) as e:
            splatray.SplatScene(sp, backend, **arrays)
        assert says in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_distance_queries_find_the_nearest_surface(points):
    """The nearest-distance queries (Open3D's compute_distance and kin):
    over a square of two triangles beside the bunny's splats, the distance
    and closest point are the square's own, signed by its normal; the
    cloud's own points lie within their noise of the splats; a cloud far
    from the origin answers as near it; bad rows raise naming the row."""
    sp = splatray.splat(points, epsilon=0.01)
    ss = splatray.SplatScene(sp, "octree", vertices=QUAD_V, faces=QUAD_F)
    first = ss.first_triangle
    q = np.array([
        [4.5, 0.5, 0.3],    # above face 0: 0.3, straight down
        [3.5, 1.5, -0.2],   # below face 1: -0.2
        [6.0, 1.0, 0.5],    # beyond the edge x = 5: sqrt 1.25
        [6.0, 3.0, 1.0],    # beyond the corner (5, 2, 0): sqrt 3
    ])
    r = ss.compute_closest_points(q)
    assert r["splat_ids"][0] == first and r["splat_ids"][1] == first + 1
    assert set(r["splat_ids"][2:]) <= {first, first + 1}
    # (The triangles are held in single precision in the splats' frame.)
    np.testing.assert_allclose(r["points"], [[4.5, 0.5, 0], [3.5, 1.5, 0], [5, 1, 0], [5, 2, 0]], atol=1e-6)
    np.testing.assert_allclose(r["normals"], [[0, 0, 1]] * 4, atol=1e-6)
    want = np.array([0.3, 0.2, np.sqrt(1.25), np.sqrt(3.0)])
    d = ss.compute_distance(q)
    assert d.dtype == np.float32 and d.shape == (4,)
    np.testing.assert_allclose(d, want, rtol=1e-6)
    np.testing.assert_allclose(ss.compute_signed_distance(q), want * [1, -1, 1, 1], rtol=1e-6)
    # Both backends: the same search over the same primitives.
    other = splatray.SplatScene(sp, "embree", vertices=QUAD_V, faces=QUAD_F)
    assert np.array_equal(other.compute_distance(points), ss.compute_distance(points))
    # The cloud's points against its splats grown at epsilon 0.01: median
    # 1.59e-3, 95th percentile 6.36e-3, 99.5 % within epsilon (seed 3).
    own = ss.compute_distance(points)
    stats = (np.median(own), np.percentile(own, 95), (own <= 0.01).mean())
    assert stats[0] < 1.8e-3 and stats[1] < 7.2e-3 and stats[2] >= 0.99, stats
    near = ss.compute_closest_points(points)
    assert (near["splat_ids"] < first).all()
    np.testing.assert_allclose(np.linalg.norm(near["points"] - points, axis=1), own, rtol=1e-5, atol=1e-9)
    # A UTM-like frame: the same splats moved far from the origin.
    shift = np.array([5.0e5, -3.0e5, 120.0])
    far = splatray.SplatScene(splatray.splat(points + shift, epsilon=0.01), "octree")
    np.testing.assert_allclose(far.compute_distance(points[::7] + shift + 0.01),
                               splatray.SplatScene(sp, "octree").compute_distance(points[::7] + 0.01), atol=2e-6)
    assert ss.compute_distance(np.zeros((0, 3))).shape == (0,)
    bad = np.zeros((9, 3))
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="query_points: row 5 holds a NaN"):
        ss.compute_distance(bad)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        ss.compute_closest_points(np.zeros((4, 2)))
