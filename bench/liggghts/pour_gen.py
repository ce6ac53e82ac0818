#!/usr/bin/env python3
"""Start of the polydisperse pour and hopper benchmarks (issue 25): N spheres with diameters
uniform in [3, 5] mm at random, non-overlapping positions in the 0.1 x 0.1 m box between
z_min and z_max (default: the floor and 0.4 m), at rest. Written as a LIGGGHTS data file
(atom_style granular: id type diameter density x y z; the box's top 0.1 m above z_max), which
both codes read: LIGGGHTS by `read_data`, ours by dem-node/benches/pour.rs. Seeded; the same
arguments give the same file on any machine.

    python3 pour_gen.py [N=20000] [seed=1] [z_min=0 z_max=0.4] > pour.data
    python3 pour_gen.py 20000 1 0.16 0.45 > hopper.data     # above the hopper's funnel
"""
import random
import sys

N = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
SEED = int(sys.argv[2]) if len(sys.argv) > 2 else 1
D_MIN, D_MAX = 0.003, 0.005
Z_MIN = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
Z_TOP = float(sys.argv[4]) if len(sys.argv) > 4 else 0.4
L, BOX_TOP = 0.1, Z_TOP + 0.1
GAP = 1e-4  # clearance between spheres and from the walls at the start, m
DENSITY = 1242.0

rng = random.Random(SEED)
cell = D_MAX + GAP
grid = {}
placed = []
attempts = 0
while len(placed) < N:
    attempts += 1
    if attempts > 200 * N:
        sys.exit(f"pour_gen.py: could place only {len(placed)} of {N} spheres; use fewer")
    d = float(f"{rng.uniform(D_MIN, D_MAX):.6e}")
    r = 0.5 * d
    x = float(f"{rng.uniform(r + GAP, L - r - GAP):.9e}")
    y = float(f"{rng.uniform(r + GAP, L - r - GAP):.9e}")
    z = float(f"{rng.uniform(Z_MIN + r + GAP, Z_TOP - r):.9e}")
    key = (int(x / cell), int(y / cell), int(z / cell))
    ok = True
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            for k in (-1, 0, 1):
                for (px, py, pz, pr) in grid.get((key[0] + i, key[1] + j, key[2] + k), ()):
                    if (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2 < (pr + r + GAP) ** 2:
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                break
        if not ok:
            break
    if ok:
        grid.setdefault(key, []).append((x, y, z, r))
        placed.append((d, x, y, z))

out = sys.stdout
out.write(f"LIGGGHTS data file: {N} spheres d in [3, 5] mm, z in [{Z_MIN}, {Z_TOP}] m, seed {SEED}\n\n")
out.write(f"{N} atoms\n1 atom types\n\n")
out.write(f"0.0 {L} xlo xhi\n0.0 {L} ylo yhi\n0.0 {BOX_TOP:g} zlo zhi\n\n")
out.write("Atoms\n\n")
for i, (d, x, y, z) in enumerate(placed, 1):
    out.write(f"{i} 1 {d:.6e} {DENSITY} {x:.9e} {y:.9e} {z:.9e}\n")
