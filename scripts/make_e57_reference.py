"""Writes an E57 file with pye57 (libE57Format, the reference C++
implementation, independent of the `e57` crate splatray reads with): two
scans of a unit sphere at a georeferenced centre, seen from opposite sides,
each in its own frame with a pose, 800 points each, with colour.

tests/data/two-scans-libe57.e57 was made by
`pip install pye57 numpy && python3 scripts/make_e57_reference.py tests/data/two-scans-libe57.e57`
(pye57 0.4.19); tests/formats.rs reads it. Not run by the tests. It also
writes FILE.truth.xyz, the points in world coordinates (not kept).
"""
import sys
import numpy as np
import pye57

centre = np.array([512345.678, 4012345.123, 100.0])
rng = np.random.default_rng(5)
out = pye57.E57(sys.argv[1], mode="w")
truth = []
for k, (off, angle) in enumerate([((4.0, 0.0, 0.0), 0.3), ((-4.0, 0.0, 1.0), 2.5)]):
    at = centre + np.array(off)
    axis = np.array([0.3, 1.0, -0.2]); axis /= np.linalg.norm(axis)
    q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])  # w x y z
    w, x, y, z = q
    R = np.array([[1-2*(y*y+z*z), 2*(x*y-w*z), 2*(x*z+w*y)],
                  [2*(x*y+w*z), 1-2*(x*x+z*z), 2*(y*z-w*x)],
                  [2*(x*z-w*y), 2*(y*z+w*x), 1-2*(x*x+y*y)]])
    pts = []
    while len(pts) < 800:
        d = rng.normal(size=3); d /= np.linalg.norm(d)
        p = centre + d
        if d @ ((at - p) / np.linalg.norm(at - p)) > 0.2:
            pts.append(p)
    pts = np.array(pts)
    local = (pts - at) @ R  # R^T (p - at) row-wise
    truth.append(pts)
    data = {
        "cartesianX": local[:, 0], "cartesianY": local[:, 1], "cartesianZ": local[:, 2],
        "colorRed": np.full(len(pts), 255 if k == 0 else 0, dtype=np.uint8),
        "colorGreen": np.full(len(pts), 128, dtype=np.uint8),
        "colorBlue": np.zeros(len(pts), dtype=np.uint8),
    }
    out.write_scan_raw(data, name=f"scan {k}", rotation=q, translation=at)
out.close()
np.savetxt(sys.argv[1] + ".truth.xyz", np.concatenate(truth), fmt="%.6f")
