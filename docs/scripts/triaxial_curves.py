#!/usr/bin/env python3
"""The triaxial test's curves from a run folder of scenes/triaxial-membrane*.toml.

    python3 docs/scripts/triaxial_curves.py out/triaxial-membrane [--block 100]
    cosim plot out/triaxial-membrane/triaxial.csv --x axial_strain --columns stress_ratio

Reads the DEM's platen (dem/dem_timeseries.csv: `platen.displacement`,
`platen.contact_force`) and the membrane's volume, top ring height and the grains' outward force
(fem/fem_probes.csv: `volume`, `top_ring_z`, `outward_force`), one row per window on both
sides, and writes <run>/triaxial.csv, block means of `--block` windows, with

    time, axial_strain, stress_ratio (σ₁/σ₃), solid_fraction (Φ), volumetric_strain
    (compression positive), lateral_share (outward force / (p × lateral area)),
    radius_change_mm (the `middle` probe's ux)

The axial strain counts from the start of shearing (the platen's `drive.start`); the cross
section is the volume inside the membrane over the height of its top ring (the seed's mean
cross section); σ₃ is the cell pressure p. Φ is the beads' solid volume (from the particle file
the scene reads, after its `keep` cut) over the volume inside the membrane. Rows from the last block
before shearing (the consolidated sample) on. Standard library only; prints the peak stress ratio and the solid fraction at a few strains.
"""

import argparse
import csv
import json
import math
import sys
import tomllib
from pathlib import Path


def columns(path, names):
    with open(path, newline="") as f:
        rows = csv.reader(f)
        head = next(rows)
        try:
            idx = [head.index(n) for n in names]
        except ValueError as e:
            sys.exit(f"{path}: {e}; columns are {', '.join(head)}")
        out = [[] for _ in names]
        for r in rows:
            if len(r) < len(head):
                break  # a row being written
            for k, i in enumerate(idx):
                out[k].append(float(r[i]))
    return out


def block_means(v, n):
    return [sum(v[i : i + n]) / len(v[i : i + n]) for i in range(0, len(v) - n + 1, n)]


def solid_volume(scene, scene_dir):
    total = 0.0
    for src in scene["dem"]["particles"]:
        if src.get("kind") != "file":
            sys.exit("the beads come from a particle file in the triaxial scenes")
        path = Path(src["path"])
        path = path if path.is_absolute() else scene_dir / path
        keep = src.get("keep", {})
        lo = keep.get("min", [-math.inf] * 3)
        hi = keep.get("max", [math.inf] * 3)
        with open(path, newline="") as f:
            rows = csv.DictReader(f)
            for r in rows:
                x = [float(r[c]) for c in ("x", "y", "z")]
                if all(lo[i] <= x[i] <= hi[i] for i in range(3)):
                    total += 4.0 / 3.0 * math.pi * float(r["radius"]) ** 3
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="the run's output folder")
    ap.add_argument("--block", type=int, default=100, help="windows per mean (default 100)")
    a = ap.parse_args()
    scene = tomllib.loads((a.run / "scene.toml").read_text())
    record = json.loads((a.run / "run.json").read_text())
    scene_dir = Path(record["scene_file"]).resolve().parent
    platen = next(w for w in scene["dem"]["walls"] if "load" in w)
    z0 = platen["point"][2]
    start = platen["load"]["drive"]["start"]
    p = next(l["value"] for l in scene["fem"]["loads"] if l["type"] == "pressure")
    solid = solid_volume(scene, scene_dir)

    t, u, f = columns(
        a.run / "dem/dem_timeseries.csv",
        ["time", "platen.displacement", "platen.contact_force"],
    )
    vol, ring, out, ux = columns(
        a.run / "fem/fem_probes.csv",
        ["volume", "top_ring_z", "outward_force", "probe.middle.ux"],
    )
    n = min(len(t), len(vol))
    t, u, f, vol, ring, out, ux = (
        block_means(c[:n], a.block) for c in (t, u, f, vol, ring, out, ux)
    )
    k0 = max(0, next((k for k, x in enumerate(t) if x > start), len(t)) - 1)
    h0, v0 = z0 + u[k0], vol[k0]
    rows = []
    for k in range(len(t)):
        h = z0 + u[k]
        area = vol[k] / ring[k]
        lateral = out[k] / (p * 2.0 * math.sqrt(math.pi * area) * ring[k])
        rows.append(
            (
                t[k],
                (h0 - h) / h0,
                f[k] / (area * p),
                solid / vol[k],
                (v0 - vol[k]) / v0,
                lateral,
                ux[k] * 1e3,
            )
        )
    dest = a.run / "triaxial.csv"
    with open(dest, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "time",
                "axial_strain",
                "stress_ratio",
                "solid_fraction",
                "volumetric_strain",
                "lateral_share",
                "radius_change_mm",
            ]
        )
        w.writerows([f"{x:.6g}" for x in r] for r in rows[k0:])
    sheared = rows[k0:]
    print(
        f"{dest}: {len(rows) - k0} rows of {a.block} windows from the start of shearing; "
        f"p = {p:g} Pa, solid {solid * 1e9:.0f} mm³"
    )
    r = rows[k0]
    print(f"consolidated (t = {r[0]:.3f} s): σ₁/σ₃ = {r[2]:.3f}, Φ = {r[3]:.4f}")
    if sheared:
        peak = max(sheared, key=lambda r: r[2])
        print(f"peak σ₁/σ₃ = {peak[2]:.3f} at axial strain {peak[1] * 100:.2f} %, Φ = {peak[3]:.4f}")
        for e in (0.01, 0.02, 0.03, 0.05, 0.075, 0.10, 0.15, 0.20, 0.25):
            r = next((r for r in sheared if r[1] >= e), None)
            if r:
                print(
                    f"  ε₁ = {e * 100:4.1f} %: σ₁/σ₃ = {r[2]:.3f}, Φ = {r[3]:.4f}, "
                    f"ε_v = {r[4] * 100:+.2f} %, lateral share {r[5]:.3f}, Δr = {r[6]:+.2f} mm"
                )


if __name__ == "__main__":
    main()
