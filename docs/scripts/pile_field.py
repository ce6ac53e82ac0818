#!/usr/bin/env python3
"""The grains' displacement field around the pile of scenes/pile*.toml.

    python3 docs/scripts/pile_field.py out/pile [--cell 2.5]

Reads the scene the run kept (<run>/scene.toml: the particle file and its `keep` cut, the
same file and cut the DEM read, so row k of the cut file is particle k) and the grains at the
end (<run>/dem/particles_final.csv: `[dem.output] final_particles = true`), bins the grains by
their starting x and z in square cells of `--cell` mm, and writes

    <run>/pile_field.csv   x_mm, z_mm (cell centres), grains, dx_mm, dz_mm (means)
    <run>/pile_dz.png      the mean vertical displacement per cell, blue down, red up
                           (8 px per mm; white where no grain started)

and prints the dz map (µm, rows from the surface down). Standard library only.
"""

import argparse
import csv
import json
import math
import struct
import sys
import tomllib
import zlib
from pathlib import Path


def read_grains(path):
    with open(path, newline="") as f:
        return [(float(r["x"]), float(r["z"])) for r in csv.DictReader(f)]


def png(path, pixels, width, height):
    """Writes an 8-bit RGB PNG of `pixels` (rows of (r, g, b))."""
    raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in pixels)

    def chunk(kind, data):
        c = struct.pack(">I", len(data)) + kind + data
        return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def colour(v, vmax):
    """Diverging blue–white–red for v in [−vmax, vmax]."""
    t = max(-1.0, min(1.0, v / vmax)) if vmax > 0 else 0.0
    if t < 0:
        return (int(255 * (1 + t)), int(255 * (1 + t)), 255)
    return (255, int(255 * (1 - t)), int(255 * (1 - t)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--cell", type=float, default=2.5, help="cell size in mm")
    a = ap.parse_args()
    scene = tomllib.loads((a.run / "scene.toml").read_text())
    sources = [s for s in scene["dem"]["particles"] if s.get("kind") == "file"]
    if len(sources) != 1:
        sys.exit("expected one particle file source in the scene")
    src = sources[0]
    path = Path(src["path"])
    if not path.is_absolute():
        # relative to the scene file's folder (summary.json names the file as it was given)
        summary = json.loads((a.run / "summary.json").read_text())
        path = Path(summary["scene_file"]).parent / path
    keep = src.get("keep", {})
    lo = keep.get("min", [-math.inf] * 3)
    hi = keep.get("max", [math.inf] * 3)
    with open(path, newline="") as f:
        start = [
            (float(r["x"]), float(r["z"]))
            for r in csv.DictReader(f)
            if all(lo[k] <= float(r[c]) <= hi[k] for k, c in enumerate("xyz"))
        ]
    end = read_grains(a.run / "dem" / "particles_final.csv")
    if len(start) != len(end):
        sys.exit(f"{len(start)} grains at the start, {len(end)} at the end: not the same run")
    h = a.cell * 1e-3
    cells = {}
    for (x0, z0), (x1, z1) in zip(start, end):
        k = (math.floor(x0 / h), math.floor(z0 / h))
        c = cells.setdefault(k, [0, 0.0, 0.0])
        c[0] += 1
        c[1] += x1 - x0
        c[2] += z1 - z0
    ix = [k[0] for k in cells]
    iz = [k[1] for k in cells]
    rows = []
    for (i, k), (n, dx, dz) in sorted(cells.items(), key=lambda e: (-e[0][1], e[0][0])):
        rows.append(((i + 0.5) * a.cell, (k + 0.5) * a.cell, n, dx / n * 1e3, dz / n * 1e3))
    with open(a.run / "pile_field.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["x_mm", "z_mm", "grains", "dx_mm", "dz_mm"])
        w.writerows(rows)
    vmax = max(abs(r[4]) for r in rows)
    scale = max(1, int(round(a.cell * 8)))  # 8 px per mm
    width = (max(ix) - min(ix) + 1) * scale
    height = (max(iz) - min(iz) + 1) * scale
    pixels = []
    for k in range(max(iz), min(iz) - 1, -1):
        line = []
        for i in range(min(ix), max(ix) + 1):
            c = cells.get((i, k))
            px = colour(c[2] / c[0] * 1e3, vmax) if c else (255, 255, 255)
            line.extend([px] * scale)
        pixels.extend([line] * scale)
    png(a.run / "pile_dz.png", pixels, width, height)
    print(f"dz (µm) by {a.cell} mm cells of the grains' start, x from {min(ix) * a.cell:.1f} mm;"
          f" colour scale ±{vmax:.2f} mm")
    for k in range(max(iz), min(iz) - 1, -1):
        cols = []
        for i in range(min(ix), max(ix) + 1):
            c = cells.get((i, k))
            cols.append(f"{c[2] / c[0] * 1e6:6.0f}" if c else "     .")
        print(f"z = {(k + 0.5) * a.cell:5.1f} " + " ".join(cols))
    print(f"wrote {a.run / 'pile_field.csv'} and {a.run / 'pile_dz.png'}")


if __name__ == "__main__":
    main()
