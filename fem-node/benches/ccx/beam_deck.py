#!/usr/bin/env python3
"""CalculiX deck of the REFERENCE A3 / D beam (1000 x 100 x 100 mm, ends clamped, 5 kPa on top),
C3D8 hexes of edge h, equivalent to `benches/static_beam.rs`.

    python3 beam_deck.py 10 > beam10.inp && /usr/bin/time -v ccx -i beam10
"""
import sys

h = float(sys.argv[1]) / 1000.0 if len(sys.argv) > 1 else 0.01
L, W, H = 1.0, 0.1, 0.1
nx, ny, nz = round(L / h), round(W / h), round(H / h)
nid = lambda i, j, k: 1 + i + (nx + 1) * (j + (ny + 1) * k)
out = ["*HEADING", f"A3 beam, C3D8, h = {h} m", "*NODE"]
for k in range(nz + 1):
    for j in range(ny + 1):
        for i in range(nx + 1):
            out.append(f"{nid(i, j, k)}, {i * L / nx:.9g}, {j * W / ny:.9g}, {k * H / nz:.9g}")
out.append("*ELEMENT, TYPE=C3D8, ELSET=BEAM")
e = 0
top = []
for k in range(nz):
    for j in range(ny):
        for i in range(nx):
            e += 1
            n = [nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i, j + 1, k),
                 nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)]
            out.append(f"{e}, " + ", ".join(map(str, n)))
            if k == nz - 1:
                top.append(e)
out.append("*NSET, NSET=ENDS")
ends = [nid(i, j, k) for k in range(nz + 1) for j in range(ny + 1) for i in (0, nx)]
for c in range(0, len(ends), 16):
    out.append(", ".join(map(str, ends[c:c + 16])))
out.append("*NSET, NSET=MID")
out.append(str(nid(nx // 2, ny // 2, nz // 2)))
out += ["*MATERIAL, NAME=STEEL", "*ELASTIC", "210e9, 0.3", "*DENSITY", "7800",
        "*SOLID SECTION, ELSET=BEAM, MATERIAL=STEEL",
        "*STEP", "*STATIC", "*BOUNDARY", "ENDS, 1, 3", "*DLOAD"]
# face 2 of C3D8 is the top face (nodes 5-8)
out += [f"{e}, P2, 5000" for e in top]
out += ["*NODE PRINT, NSET=MID", "U", "*END STEP"]
print("\n".join(out))
