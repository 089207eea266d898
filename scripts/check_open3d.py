"""Reads a splat file with Open3D's standard reader and plyfile and checks
that Open3D sees the colours, normals and positions the file holds.

Not part of the test suite (Open3D is a 400 MB wheel that also needs
libusb-1.0): `pip install open3d plyfile`, then
`python3 scripts/check_open3d.py SPLATS.ply`.
"""
import sys
import numpy as np
import open3d as o3d
from plyfile import PlyData

path = sys.argv[1]
pc = o3d.io.read_point_cloud(path)
c = np.asarray(pc.colors); n = np.asarray(pc.normals); p = np.asarray(pc.points)
d = PlyData.read(path)['vertex']
rgb = np.stack([d['red'], d['green'], d['blue']], 1).astype(float)
print(f"open3d {o3d.__version__}: {len(p)} points, colors {pc.has_colors()}, normals {pc.has_normals()}")
print("first colour x255:", np.round(c[0] * 255).astype(int).tolist(), "uchar:", rgb[0].astype(int).tolist())
print("max |open3d colour x255 - uchar|:", np.abs(np.round(c * 255) - rgb).max())
print("max |open3d normal - nx ny nz|:", np.abs(n - np.stack([d['nx'], d['ny'], d['nz']], 1)).max())
print("max |open3d point - x y z|:", np.abs(p - np.stack([d['x'], d['y'], d['z']], 1)).max())
