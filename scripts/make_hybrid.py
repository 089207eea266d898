#!/usr/bin/env python3
"""Writes the triangle models of scenes/hybrid.toml (issue 57) into scenes/data/:
a table of boxes and a mirror quad (OBJ, face normals) and a lamp shade
(ASCII PLY with unit vertex normals). Run from the repository root."""
import math
def sub(a,b): return [a[i]-b[i] for i in range(3)]
def cross(a,b): return [a[1]*b[2]-a[2]*b[1],a[2]*b[0]-a[0]*b[2],a[0]*b[1]-a[1]*b[0]]
def dot(a,b): return sum(a[i]*b[i] for i in range(3))
def orient(V,t,out):
    n=cross(sub(V[t[1]],V[t[0]]),sub(V[t[2]],V[t[0]]))
    return t if dot(n,out)>0 else (t[0],t[2],t[1])
def box(V,F,lo,hi):
    base=len(V)
    for i in range(8):
        V.append([hi[0] if i&1 else lo[0], hi[1] if i&2 else lo[1], hi[2] if i&4 else lo[2]])
    c=[(lo[i]+hi[i])/2 for i in range(3)]
    quads=[(0,1,3,2),(4,5,7,6),(0,1,5,4),(2,3,7,6),(0,2,6,4),(1,3,7,5)]
    for q in quads:
        q=[base+k for k in q]
        for t in [(q[0],q[1],q[2]),(q[0],q[2],q[3])]:
            cen=[sum(V[k][i] for k in t)/3 for i in range(3)]
            F.append(orient(V,t,sub(cen,c)))
def obj(path,V,F,comment):
    with open(path,'w') as f:
        f.write(f"# {comment}\n")
        for v in V: f.write("v %g %g %g\n"%tuple(round(x,6) for x in v))
        for t in F: f.write("f %d %d %d\n"%(t[0]+1,t[1]+1,t[2]+1))
# Table: a top and four legs.
V=[];F=[]
box(V,F,[-1.6,-0.08,-1.0],[1.6,0.0,1.0])
for x in (-1.45,1.37):
    for z in (-0.85,0.77):
        box(V,F,[x,-1.2,z],[x+0.08,-0.08,z+0.08])
obj('scenes/data/hybrid-table.obj',V,F,"issue 57's hybrid scene: a table of 5 boxes, 60 triangles, face normals (made by scripts/make_hybrid.py)")
# Mirror: one quad standing on the table, facing +z.
V=[[-1.3,0.0,-0.9],[0.5,0.0,-0.9],[0.5,1.1,-0.9],[-1.3,1.1,-0.9]]
F=[(0,1,2),(0,2,3)]
obj('scenes/data/hybrid-mirror.obj',V,F,"issue 57's hybrid scene: a mirror, one quad (made by scripts/make_hybrid.py)")
# Lamp shade: an open frustum with smooth (vertex) normals, ascii PLY.
N=48; rb,rt,y0,y1=0.55,0.28,1.05,1.55; cx,cz=0.1,0.1
V=[];NV=[];F=[]
h=y1-y0
for i in range(N):
    a=2*math.pi*i/N
    for r,y in ((rb,y0),(rt,y1)):
        V.append([cx+r*math.cos(a),y,cz+r*math.sin(a)])
        n=[h*math.cos(a),rb-rt,h*math.sin(a)]; l=math.sqrt(dot(n,n))
        NV.append([x/l for x in n])
for i in range(N):
    j=(i+1)%N
    b0,t0,b1,t1=2*i,2*i+1,2*j,2*j+1
    for t in [(b0,t0,b1),(b1,t0,t1)]:
        out=[sum(NV[k][d] for k in t) for d in range(3)]
        F.append(orient(V,t,out))
with open('scenes/data/hybrid-shade.ply','w') as f:
    f.write("ply\nformat ascii 1.0\ncomment issue 57's hybrid scene: a lamp shade, an open frustum of %d triangles with unit vertex normals, made by scripts/make_hybrid.py\n"%len(F))
    f.write("element vertex %d\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"%len(V))
    f.write("element face %d\nproperty list uchar int vertex_indices\nend_header\n"%len(F))
    for v,n in zip(V,NV): f.write("%g %g %g %g %g %g\n"%tuple(round(x,6) for x in v+n))
    for t in F: f.write("3 %d %d %d\n"%t)
