#!/usr/bin/env python3
"""The highest surface point of a settled bed: where to put the compaction plate or the sleeper.

    python3 docs/scripts/bed_top.py out/sleeper-bed-poly/dem/particles_final.csv
    python3 docs/scripts/bed_top.py out/sleeper-compact-poly/dem/particles_final.csv \\
        --below 0.8 --xy 0.35 2.85 0.4 0.6

Reads a particle file written by `[dem.output] final_particles = true` (spheres: x, y, z,
radius; dilated polyhedra also qw..qz, stone, size and the stone library beside it,
particles_final.stones.json) and prints, over the particles whose centre lies at or below
`--below` (what a scene's `keep = { max = [.., .., level] }` leaves) and inside the x–y box
`--xy xmin xmax ymin ymax`, the highest point of their surfaces: z + r for a sphere,
z + size (max over the rotated core vertices of their z + dilation) for a stone — the same
rule as `bed_top` in tests/tests/polyhedra.rs. Also prints the 95th percentile of the
particle tops and the count, and with `--cell 0.1` how flat the surface is: the highest top
in each 10 × 10 cm cell of the box, 10th–90th percentile over the cells. Superquadrics count
with their bounding radius. Standard library only.
"""

import argparse
import csv
import json
import sys
from pathlib import Path


def tops(path, below, xy):
    """(x, y, top z) of every particle selected (centre ≤ below, inside xy)."""
    stones = None
    out = []
    with open(path, newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                x, y, z = float(row["x"]), float(row["y"]), float(row["z"])
            except (KeyError, ValueError) as e:
                sys.exit(f"{path}:{line}: x, y, z: {e}")
            if z > below or not (xy[0] <= x <= xy[1] and xy[2] <= y <= xy[3]):
                continue
            stone = (row.get("stone") or "").strip()
            if not stone:
                out.append((x, y, z + float(row["radius"])))
                continue
            if stones is None:
                lib = Path(path).with_name(Path(path).stem + ".stones.json")
                try:
                    stones = json.loads(lib.read_text())
                except OSError as e:
                    sys.exit(f"{path}:{line}: a stone needs its library {lib}: {e}")
            k = int(stone)
            if not 0 <= k < len(stones):
                sys.exit(f"{path}:{line}: stone {k} is not in the library ({len(stones)} stones)")
            s, size = stones[k], float(row["size"])
            w, a, b, c = (float(row[q]) for q in ("qw", "qx", "qy", "qz"))
            # z component of q v q* for the unit quaternion q = (w, a, b, c)
            highest = max(
                2.0 * (a * c - w * b) * v[0]
                + 2.0 * (b * c + w * a) * v[1]
                + (w * w - a * a - b * b + c * c) * v[2]
                for v in s["vertices"]
            )
            out.append((x, y, z + size * (highest + s["dilation"])))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("particles", help="a particles_final.csv")
    ap.add_argument("--below", type=float, default=float("inf"),
                    help="only particles whose centre is at or below this z (m)")
    ap.add_argument("--xy", type=float, nargs=4, metavar=("XMIN", "XMAX", "YMIN", "YMAX"),
                    default=[-float("inf"), float("inf")] * 2,
                    help="only particles whose centre lies in this x-y box (m)")
    ap.add_argument("--cell", type=float, help="also the surface's flatness over square cells of this size (m)")
    args = ap.parse_args()
    selected = tops(args.particles, args.below, args.xy)
    t = sorted(z for _, _, z in selected)
    if not t:
        sys.exit(f"{args.particles}: no particle below z = {args.below} in the box {args.xy}")
    p95 = t[min(len(t) - 1, int(0.95 * len(t)))]
    print(f"highest surface point {t[-1]:.4f} m; 95 % of the tops below {p95:.4f} m; "
          f"{len(t)} particles")
    if args.cell:
        cells = {}
        for x, y, z in selected:
            key = (int(x // args.cell), int(y // args.cell))
            cells[key] = max(cells.get(key, z), z)
        c = sorted(cells.values())
        pick = lambda q: c[min(len(c) - 1, int(q * len(c)))]
        print(f"highest top per {args.cell} m cell: 10th-90th percentile {pick(0.1):.4f}-"
              f"{pick(0.9):.4f} m over {len(c)} cells")


if __name__ == "__main__":
    main()
