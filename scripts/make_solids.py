#!/usr/bin/env python3
"""Writes scenes/data/solids.ply: closed solids with flat faces, edges and
corners on a ground plane (issue 39's test data): a box, a gable-roofed
block and a cylinder with a flat cap, y up, each face wound outward (its
normal by the right-hand rule). No bottoms: they stand on the ground.
Usage: python3 scripts/make_solids.py [OUT.ply]"""
import math
import sys

verts, faces = [], []


def quad(a, b, c, d):
    """Two triangles a b c, a c d (counter-clockwise seen from outside)."""
    i = len(verts)
    verts.extend([a, b, c, d])
    faces.append((i, i + 1, i + 2))
    faces.append((i, i + 2, i + 3))


def tri(a, b, c):
    i = len(verts)
    verts.extend([a, b, c])
    faces.append((i, i + 1, i + 2))


G = 1.2
quad((-G, 0, -G), (-G, 0, G), (G, 0, G), (G, 0, -G))  # ground, +y

# Box x in [-0.9, -0.1], z in [-0.8, -0.2], height 0.5.
x0, x1, z0, z1, h = -0.9, -0.1, -0.8, -0.2, 0.5
quad((x0, h, z0), (x0, h, z1), (x1, h, z1), (x1, h, z0))  # top +y
quad((x0, 0, z1), (x1, 0, z1), (x1, h, z1), (x0, h, z1))  # +z
quad((x1, 0, z0), (x0, 0, z0), (x0, h, z0), (x1, h, z0))  # -z
quad((x1, 0, z1), (x1, 0, z0), (x1, h, z0), (x1, h, z1))  # +x
quad((x0, 0, z0), (x0, 0, z1), (x0, h, z1), (x0, h, z0))  # -x

# Gable-roofed block: x in [0.15, 0.85], z in [-0.6, 0.5], eaves 0.4,
# ridge 0.7 along z.
x0, x1, z0, z1, h, r = 0.15, 0.85, -0.6, 0.5, 0.4, 0.7
xm = 0.5 * (x0 + x1)
quad((x1, 0, z1), (x1, 0, z0), (x1, h, z0), (x1, h, z1))  # +x wall
quad((x0, 0, z0), (x0, 0, z1), (x0, h, z1), (x0, h, z0))  # -x wall
quad((x0, 0, z1), (x1, 0, z1), (x1, h, z1), (x0, h, z1))  # +z gable wall
tri((x0, h, z1), (x1, h, z1), (xm, r, z1))
quad((x1, 0, z0), (x0, 0, z0), (x0, h, z0), (x1, h, z0))  # -z gable wall
tri((x1, h, z0), (x0, h, z0), (xm, r, z0))
quad((x1, h, z1), (x1, h, z0), (xm, r, z0), (xm, r, z1))  # +x roof
quad((x0, h, z0), (x0, h, z1), (xm, r, z1), (xm, r, z0))  # -x roof

# Cylinder: centre (-0.45, 0.45), radius 0.3, height 0.45, 64 sides.
cx, cz, rad, h, n = -0.45, 0.45, 0.3, 0.45, 64
ring = [(cx + rad * math.cos(2 * math.pi * k / n), cz + rad * math.sin(2 * math.pi * k / n))
        for k in range(n)]
for k in range(n):
    (ax, az), (bx, bz) = ring[k], ring[(k + 1) % n]
    quad((bx, 0, bz), (ax, 0, az), (ax, h, az), (bx, h, bz))  # side, outward
    tri((cx, h, cz), (bx, h, bz), (ax, h, az))  # cap, +y

out = sys.argv[1] if len(sys.argv) > 1 else "scenes/data/solids.ply"
with open(out, "w") as f:
    f.write("ply\nformat ascii 1.0\ncomment made by scripts/make_solids.py\n")
    f.write(f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n")
    f.write(f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    for v in verts:
        f.write("%g %g %g\n" % v)
    for a, b, c in faces:
        f.write(f"3 {a} {b} {c}\n")
