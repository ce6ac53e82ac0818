#!/usr/bin/env python3
"""Several triaxial runs side by side: one CSV, one column per run, on a common strain grid.

    python3 docs/scripts/triaxial_pressures.py --out docs/figures/triaxial-membrane-pressures \\
        25=out/triaxial-membrane-pressures/run000 100=out/triaxial-membrane ...
    cosim plot docs/figures/triaxial-membrane-pressures_stress_ratio.csv --x axial_strain_pct

Each argument is LABEL=RUN, RUN a folder where docs/scripts/triaxial_curves.py has written
triaxial.csv (LABEL: the cell pressure in kPa). Writes <out>_stress_ratio.csv and
<out>_solid_fraction.csv: the axial strain in % every 0.25 % from 0 to the shortest run's end,
and per run the value interpolated linearly between its block means, in a column named
`p<LABEL>kPa`. Prints each run's peak ratio and the values at a few strains. Standard library
only.
"""

import argparse
import csv
import sys
from pathlib import Path


def read(run):
    path = Path(run) / "triaxial.csv"
    if not path.is_file():
        sys.exit(f"{path}: missing (run docs/scripts/triaxial_curves.py {run} first)")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if len(rows) < 2:
        sys.exit(f"{path}: fewer than two rows")
    try:
        return [
            (float(r["axial_strain"]), float(r["stress_ratio"]), float(r["solid_fraction"]))
            for r in rows
        ]
    except (KeyError, ValueError) as e:
        sys.exit(f"{path}: {e}")


def at(rows, k, strain):
    """Column k of rows linearly interpolated at the axial strain `strain` (rows ascending)."""
    for (e0, *a), (e1, *b) in zip(rows, rows[1:]):
        if e0 <= strain <= e1:
            w = 0.0 if e1 == e0 else (strain - e0) / (e1 - e0)
            return a[k] + w * (b[k] - a[k])
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", metavar="LABEL=RUN")
    ap.add_argument("--out", required=True, help="output prefix")
    ap.add_argument("--step", type=float, default=0.25, help="strain step in %% [0.25]")
    args = ap.parse_args()
    runs = []
    for arg in args.runs:
        label, sep, run = arg.partition("=")
        if not sep or not label or not run:
            sys.exit(f"`{arg}`: expected LABEL=RUN, e.g. 25=out/triaxial-membrane-pressures/run000")
        rows = sorted(read(run))
        runs.append((label, rows))
    end = min(rows[-1][0] for _, rows in runs)
    grid = [i * args.step / 100 for i in range(int(end * 100 / args.step + 1e-9) + 1)]
    for k, name in [(0, "stress_ratio"), (1, "solid_fraction")]:
        out = Path(f"{args.out}_{name}.csv")
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["axial_strain_pct"] + [f"p{label}kPa" for label, _ in runs])
            for e in grid:
                vals = [at(rows, k, e) for _, rows in runs]
                w.writerow([f"{100 * e:.2f}"] + ["" if v is None else f"{v:.5f}" for v in vals])
        print(f"{out}: {len(grid)} rows, {len(runs)} runs")
    for label, rows in runs:
        peak = max(rows, key=lambda r: r[1])
        marks = ", ".join(
            f"{p} %: {at(rows, 0, p / 100):.3f}" for p in (1, 3, 5, 10, 20) if p / 100 <= rows[-1][0]
        )
        print(f"p = {label} kPa: peak σ₁/σ₃ {peak[1]:.3f} at {100 * peak[0]:.1f} %, Φ {rows[0][2]:.4f} → {rows[-1][2]:.4f}; {marks}")


if __name__ == "__main__":
    main()
