#!/usr/bin/env python3
"""The figures of a full-size sleeper run (scenes/sleeper.toml, scenes/sleeper-poly.toml) for
docs/full-size.md: settlement, sensor pressures at the seed's load levels, strains, the
ballast's kinetic energy and the run's cost.

    python3 docs/scripts/sleeper_figures.py out/sleeper-poly [--shift 0.0]

prints the tables and writes, into the run folder, `settlement.csv` (mm, downward positive)
and `pressure_distribution.csv` / `_deep.csv` (the sensors' x against the pressure in kPa at
each load level, 0.13 / 0.26 m deep), which `cosim plot` draws:

    cosim plot out/sleeper-poly/settlement.csv --ylabel 'settlement (mm)'
    cosim plot out/sleeper-poly/pressure_distribution.csv --ylabel 'pressure (kPa)'
    cosim plot out/sleeper-poly/dem/dem_sensors.csv --columns p1,p2,p3,p4,p5 --scale 1e-3 \
        --ylabel 'pressure at 0.13 m (kPa)'

Load levels (U §6.3, fig. 6.14): 44 kN and 132 kN in total (0.2 and 0.6 of the two rail
seats' 220 kN peak) on the ramps before (0.05-0.08 s) and after (0.14-0.17 s) the cycles;
each pressure is the mean over +-1 ms around the level. `--shift` moves the pattern earlier
(0.04 for scenes/sleeper-poly-window.toml). Only the standard library is used.
"""

import argparse
import csv
import json
import os
import sys

SENSOR_X = [0.84, 1.22, 1.60, 1.98, 2.36]  # the sensors' centres along the sleeper (m)


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    cols = {h: [] for h in head}
    for r in rows[1:]:
        if len(r) != len(head):
            continue  # a row being written
        for h, v in zip(head, r):
            cols[h].append(float(v) if v else float("nan"))
    return cols


def mean_around(t, y, t0, half=1e-3):
    vals = [v for ti, v in zip(t, y) if abs(ti - t0) <= half + 1e-12]
    if not vals:
        return float("nan")
    return sum(vals) / len(vals)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", help="the run's output folder, e.g. out/sleeper-poly")
    ap.add_argument("--shift", type=float, default=0.0, help="the pattern starts this much earlier (s)")
    a = ap.parse_args()
    run = a.run
    sh = a.shift
    try:
        sensors = read(os.path.join(run, "dem", "dem_sensors.csv"))
        probes = read(os.path.join(run, "fem", "fem_probes.csv"))
        dem = read(os.path.join(run, "dem", "dem_timeseries.csv"))
    except FileNotFoundError as e:
        sys.exit(f"sleeper_figures: {e.filename}: not found (has the run written it?)")
    t_end = probes["time"][-1]
    print(f"{run}: simulated to {t_end:.4f} s")

    # settlement: the probes' downward displacement in mm
    with open(os.path.join(run, "settlement.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "middle", "seat"])
        w.writerow(["0", "0", "0"])  # the start (also keeps `cosim plot` on a linear axis)
        for t, m, s in zip(probes["time"], probes["probe.middle.uz"], probes["probe.seat.uz"]):
            w.writerow([f"{t:.6e}", f"{-1e3 * m:.6e}", f"{-1e3 * s:.6e}"])
    st = probes["time"]
    print("\nsettlement (mm, mean over +-1 ms), middle / seat:")
    for label, t0 in [
        ("end of settling", 0.05 - sh),
        ("first peak", 0.08 - sh),
        ("after the cycles", 0.14 - sh),
        ("second peak", 0.17 - sh),
    ]:
        if t0 <= t_end + 1e-9:
            m = -1e3 * mean_around(st, probes["probe.middle.uz"], t0)
            s = -1e3 * mean_around(st, probes["probe.seat.uz"], t0)
            print(f"  {label:18s} t = {t0:.3f} s: {m:6.1f} / {s:6.1f}")

    # pressures at the load levels, both depths
    levels = [
        ("44 kN before the cycles", 0.056 - sh),
        ("132 kN before", 0.068 - sh),
        ("first peak, 220 kN", 0.08 - sh),
        ("44 kN after the cycles", 0.146 - sh),
        ("132 kN after", 0.158 - sh),
        ("second peak, 220 kN", 0.17 - sh),
    ]
    levels = [(n, t0) for n, t0 in levels if t0 <= t_end + 1e-9]
    t = sensors["time"]
    dist = {}
    for suffix, depth in [("", "0.13 m"), ("_deep", "0.26 m")]:
        names = [f"p{i}{suffix}" for i in range(1, 6)]
        if not all(n in sensors for n in names):
            continue
        print(f"\npressure at {depth} depth (kPa, mean over +-1 ms), p1 ... p5:")
        for label, t0 in levels:
            ps = [1e-3 * mean_around(t, sensors[n], t0) for n in names]
            dist[f"{label} ({depth})"] = ps
            print(f"  {label:24s} t = {t0:.3f} s: " + ", ".join(f"{p:5.0f}" for p in ps))
        # range during the cycles (4.4-44 kN)
        c0, c1 = 0.085 - sh, 0.14 - sh
        if t_end > c0:
            vals = [v for ti, row in zip(t, zip(*[sensors[n] for n in names])) if c0 <= ti <= c1 for v in row]
            if vals:
                print(f"  during the cycles ({c0:.3f}-{min(c1, t_end):.3f} s): {1e-3 * min(vals):.0f}-{1e-3 * max(vals):.0f} kPa")

    # one file per depth (four curves each: a plot stays readable)
    for depth, name in [("0.13 m", "pressure_distribution.csv"), ("0.26 m", "pressure_distribution_deep.csv")]:
        keys = [k for k in dist if "peak" not in k and depth in k]
        if not keys:
            continue
        with open(os.path.join(run, name), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["x"] + [k.replace(f" ({depth})", "") for k in keys])
            for i, x in enumerate(SENSOR_X):
                w.writerow([f"{x:.3f}"] + [f"{dist[k][i]:.3f}" for k in keys])

    # strains and the ballast
    for col, what in [("strain.sleeper.max_principal", "largest"), ("strain.sleeper.min_principal", "smallest")]:
        if col in probes:
            ys = probes[col]
            i = max(range(len(ys)), key=lambda k: abs(ys[k]))
            print(f"\n{what} principal strain: {ys[i]:.3e} at {st[i]:.4f} s", end="")
    print()
    ke = dem["kinetic_energy"]
    i = max(range(len(ke)), key=lambda k: ke[k])
    print(f"ballast kinetic energy: peak {ke[i]:.1f} J at {dem['time'][i]:.4f} s, end {ke[-1]:.2f} J")

    # the cost
    try:
        with open(os.path.join(run, "summary.json")) as f:
            s = json.load(f)
        tm = s["timing"]
        print(
            f"\nstatus {s['status']}, {s['windows_done']} of {s['windows_planned']} windows; wall {tm['total_wall_s']:.0f} s: "
            f"DEM {tm['dem_compute_s']:.0f} s, FEM {tm['fem_compute_s']:.0f} s, coupling {tm['coupling_overhead_s']:.1f} s "
            f"= {100 * tm['coupling_overhead_fraction']:.2f} %"
        )
    except (FileNotFoundError, KeyError) as e:
        print(f"\nno timing ({e})")


if __name__ == "__main__":
    main()
