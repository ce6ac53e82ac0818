#!/usr/bin/env python3
"""Mean and spread of an ensemble of periodic-RVE triaxial runs (W Table 5.2).

    python3 docs/scripts/rve_ensemble.py out/rve-ensemble-L10/run0* \\
        --table docs/figures/rve-ensemble-L10.csv --curves docs/figures/rve-ensemble-L10-curves.csv
    cosim plot docs/figures/rve-ensemble-L10-curves.csv --x axial_strain_pct \\
        --columns ratio_mean,ratio_lo,ratio_hi

Reads each run folder's dem/periodic.csv (one row per window), scene.toml (the seed, the
cell's edge and the grain count) and summary.json (status, wall time), and takes the shear
from the programme's last stage: the axial strain is −stage_strain_z (compression positive),
the volumetric strain counts from the shear's start (dilation positive), σ1/σ3 is the
`stress_ratio` column. Per run:

    final       σ1/σ3, mean of the rows with axial strain in [15 %, 20 %] (W's final value)
    final_al    the same of the axial stress over the mean lateral stress (W's definition,
                §4.3.4; within ≈ 1 % of σ1/σ3 at the shear's end)
    images      dem.periodic.image_velocity: shifted (ours) or copied (the thesis's ghosts)
    end         σ1/σ3, mean of the last 20 rows of the shear (the programme's end)
    peak        largest σ1/σ3 and its axial strain
    dilatancy   Δε_V/Δε_a between 10 % and 15 % axial strain (W: 0.175 at L = 10 mm)
    phi0, phi   Φ at the shear's start and end

Runs whose programme has not ended are listed as incomplete and left out of the mean.
`--table` writes the per-run rows, `--curves` the ensemble's mean curve (and mean ± one s.d.)
of σ1/σ3 and ε_V every 0.5 % of axial strain, with each run's own columns: small files that
keep the results when the run folders are gone. Standard library only.
"""

import argparse
import csv
import json
import math
import statistics
import sys
import tomllib
from pathlib import Path

STEP = 0.5  # % axial strain between curve points


def interp(xs, ys, x):
    """Linear interpolation of the (increasing) samples xs, ys at x; None outside."""
    if not xs or x < xs[0] or x > xs[-1]:
        return None
    lo, hi = 0, len(xs) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    if xs[hi] == xs[lo]:
        return ys[lo]
    t = (x - xs[lo]) / (xs[hi] - xs[lo])
    return ys[lo] + t * (ys[hi] - ys[lo])


def read_run(folder: Path):
    scene = tomllib.loads((folder / "scene.toml").read_text())
    dem = scene["dem"]
    fill = dem["particles"][0]
    size = dem["periodic"]["size"]
    edge = size if isinstance(size, (int, float)) else size[0]
    summary = json.loads((folder / "summary.json").read_text()) if (folder / "summary.json").exists() else {}
    with open(folder / "dem" / "periodic.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        print(f"{folder}: left out, dem/periodic.csv has no rows yet", file=sys.stderr)
        return None
    stages = len(dem["periodic"]["stages"])
    shear = [r for r in rows if round(float(r["stage"])) == stages - 1]
    if not shear:
        print(f"{folder}: left out, its shear (stage {stages - 1}) has not started", file=sys.stderr)
        return None
    strain = [-100.0 * float(r["stage_strain_z"]) for r in shear]
    ratio = [float(r["stress_ratio"]) for r in shear]
    axial = [float(r["stress_zz"]) / (0.5 * (float(r["stress_xx"]) + float(r["stress_yy"])))
             for r in shear]
    # (V − V_0)/V_0 with V_0 the cell's volume at the shear's start
    ev = [100.0 * float(r["stage_volumetric_strain"]) for r in shear]
    # keep the part where the axial strain grows (the held rest after the programme is not)
    keep = [0]
    for i in range(1, len(strain)):
        if strain[i] > strain[keep[-1]]:
            keep.append(i)
    strain = [strain[i] for i in keep]
    ratio = [ratio[i] for i in keep]
    axial = [axial[i] for i in keep]
    ev = [ev[i] for i in keep]
    # the programme ended: a row after its last stage (the held cell)
    done = any(round(float(r["stage"])) >= stages for r in rows)
    band = [r for s, r in zip(strain, ratio) if 15.0 <= s <= 20.0]
    band_al = [r for s, r in zip(strain, axial) if 15.0 <= s <= 20.0]
    k = max(range(len(ratio)), key=ratio.__getitem__)
    e10, e15 = interp(strain, ev, 10.0), interp(strain, ev, 15.0)
    return {
        "run": folder.name,
        "seed": fill.get("seed", 1),
        "edge_m": edge,
        "grains": fill.get("count"),
        "images": dem["periodic"].get("image_velocity", "shifted"),
        "status": summary.get("status", "?"),
        "complete": done,
        "wall_s": summary.get("timing", {}).get("total_wall_s"),
        "phi0": float(shear[0]["solid_fraction"]),
        "phi": float(shear[keep[-1]]["solid_fraction"]),
        "final": statistics.fmean(band) if band else None,
        "final_al": statistics.fmean(band_al) if band_al else None,
        "end": statistics.fmean(ratio[-20:]),
        "peak": ratio[k],
        "peak_at_pct": strain[k],
        "dilatancy": (e15 - e10) / 5.0 if e10 is not None and e15 is not None else None,
        "curve": (strain, ratio, ev),
    }


def fmt(v, digits=4):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--table", type=Path, help="per-run CSV to write")
    ap.add_argument("--curves", type=Path, help="ensemble curve CSV to write")
    a = ap.parse_args()
    runs = [r for f in a.runs if (f / "dem" / "periodic.csv").exists() and (r := read_run(f))]
    if not runs:
        raise SystemExit("no run folder with dem/periodic.csv")
    cols = ["run", "seed", "edge_m", "grains", "images", "status", "complete", "wall_s", "phi0",
            "phi", "final", "final_al", "end", "peak", "peak_at_pct", "dilatancy"]
    w = csv.writer(sys.stdout)
    w.writerow(cols)
    for r in runs:
        w.writerow([fmt(r[c]) for c in cols])
    full = [r for r in runs if r["complete"]]
    print(f"\n{len(full)} complete of {len(runs)} runs")
    for key in ["images", "edge_m"]:
        kinds = sorted({str(r[key]) for r in full})
        if len(kinds) > 1:
            print(f"warning: the runs mix {key} = {', '.join(kinds)}: the statistics below "
                  "are over different cells", file=sys.stderr)
    for c in ["phi0", "phi", "final", "final_al", "end", "peak", "peak_at_pct", "dilatancy",
              "wall_s"]:
        vals = [r[c] for r in full if r[c] is not None]
        if vals:
            sd = statistics.stdev(vals) if len(vals) > 1 else float("nan")
            print(f"  {c:12s} mean {statistics.fmean(vals):.4g}  s.d. {sd:.2g}  "
                  f"(min {min(vals):.4g}, max {max(vals):.4g})")
    if a.table:
        with open(a.table, "w", newline="") as f:
            tw = csv.writer(f)
            tw.writerow(cols)
            for r in runs:
                tw.writerow([fmt(r[c], 6) for c in cols])
    if a.curves and full:
        top = min(r["curve"][0][-1] for r in full)
        n = int(math.floor(top / STEP + 1e-9))
        names = [f"seed{r['seed']}" for r in full]
        with open(a.curves, "w", newline="") as f:
            cw = csv.writer(f)
            cw.writerow(["axial_strain_pct", "ratio_mean", "ratio_lo", "ratio_hi", "ev_mean_pct",
                         "ev_lo_pct", "ev_hi_pct"]
                        + [f"ratio_{s}" for s in names] + [f"ev_pct_{s}" for s in names])
            for i in range(1, n + 1):
                x = i * STEP
                rs = [interp(r["curve"][0], r["curve"][1], x) for r in full]
                es = [interp(r["curve"][0], r["curve"][2], x) for r in full]
                rm, em = statistics.fmean(rs), statistics.fmean(es)
                rsd = statistics.stdev(rs) if len(rs) > 1 else 0.0
                esd = statistics.stdev(es) if len(es) > 1 else 0.0
                cw.writerow([f"{x:g}", f"{rm:.5g}", f"{rm - rsd:.5g}", f"{rm + rsd:.5g}",
                             f"{em:.5g}", f"{em - esd:.5g}", f"{em + esd:.5g}"]
                            + [f"{v:.5g}" for v in rs] + [f"{v:.5g}" for v in es])


if __name__ == "__main__":
    main()
