#!/usr/bin/env python3
"""Mesh of the REFERENCE A3 / D beam (1000 x 100 x 100 mm) in C3D8 hexes of edge h mm, for the
CalculiX decks beam_10mm.inp / beam_5mm.inp, which *INCLUDE it (the mesh is generated, not
committed: the 5 mm one is ~8 MB). Same nodes, numbering and sets as
fem-node/benches/ccx/beam_deck.py, which writes the whole deck in one file; this file only
splits the physics (committed, readable) from the mesh (generated).

    python3 beam_mesh.py 10 > mesh_10mm.inp

Sets: NSET ENDS (all nodes of the faces x = 0 and x = L, clamped), NSET MID (the node at
(0.5, 0.05, 0.05) m, the static_beam probe "midspan"), ELSET BEAM (all), ELSET TOP (the
elements of the top layer, whose face 2 -- nodes 5-8 -- lies on z = H).
"""
import sys

h = float(sys.argv[1]) / 1000.0 if len(sys.argv) > 1 else 0.01
L, W, H = 1.0, 0.1, 0.1
nx, ny, nz = round(L / h), round(W / h), round(H / h)
if nx % 2 or ny % 2 or nz % 2:
    sys.exit(f"h = {h} m: need an even number of elements along each edge (mid-span node)")


def nid(i, j, k):
    return 1 + i + (nx + 1) * (j + (ny + 1) * k)


w = sys.stdout.write
w(f"** A3 / D beam mesh, C3D8, h = {h:g} m: {nx} x {ny} x {nz} elements, "
  f"{(nx + 1) * (ny + 1) * (nz + 1)} nodes\n*NODE\n")
for k in range(nz + 1):
    for j in range(ny + 1):
        for i in range(nx + 1):
            w(f"{nid(i, j, k)}, {i * L / nx:.9g}, {j * W / ny:.9g}, {k * H / nz:.9g}\n")
w("*ELEMENT, TYPE=C3D8, ELSET=BEAM\n")
e = 0
for k in range(nz):
    for j in range(ny):
        for i in range(nx):
            e += 1
            n = (nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i, j + 1, k),
                 nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1))
            w(f"{e}, " + ", ".join(map(str, n)) + "\n")
last = nid(nx, ny, nz)
w("*NSET, NSET=ENDS, GENERATE\n")
w(f"1, {last - nx}, {nx + 1}\n")  # x = 0: nodes 1, 1 + (nx+1), ...
w(f"{nx + 1}, {last}, {nx + 1}\n")  # x = L
w(f"*NSET, NSET=MID\n{nid(nx // 2, ny // 2, nz // 2)}\n")
w(f"*ELSET, ELSET=TOP, GENERATE\n{(nz - 1) * nx * ny + 1}, {nz * nx * ny}, 1\n")
