#!/usr/bin/env python3
"""How well the fixes' reported σ covers their error, from `ground-sim descent --histories` CSVs.

For each CSV: the accepted TRN fixes' NEES (2 dof; 2 on average if their σ is right) overall,
by altitude band and by quartile of the claimed variance (east + north), and the filter's
horizontal NEES in the 95 % band (0.05-7.38) by fifth of each run's flight time. Used in
docs/registration.md ("The shape of the short σ", session 46).

    tools/.venv/bin/python tools/fix_sigma_shape.py histories.csv [more.csv ...]
"""
import csv
import sys

import numpy as np


def num(row, key):
    v = row[key]
    return float(v) if v not in ("", "NaN", "nan", "inf") else np.nan


def report(path):
    rows = list(csv.DictReader(open(path)))
    err2, trace, nees, alt = [], [], [], []
    for r in rows:
        if r["fix_state"] != "1" or r["fix_e_m"] == "":
            continue
        e = np.array([num(r, "fix_e_m") - num(r, "truth_e_m"), num(r, "fix_n_m") - num(r, "truth_n_m")])
        c = np.array(
            [
                [num(r, "fix_cov_ee_m2"), num(r, "fix_cov_en_m2")],
                [num(r, "fix_cov_en_m2"), num(r, "fix_cov_nn_m2")],
            ]
        )
        err2.append(e @ e)
        trace.append(np.trace(c))
        nees.append(e @ np.linalg.solve(c, e))
        alt.append(num(r, "truth_u_m"))
    err2, trace, nees, alt = map(np.array, (err2, trace, nees, alt))
    print(f"{path}: {len(nees)} fixes, mean NEES {nees.mean():.2f}, "
          f"share under the 95 % point (5.99) {np.mean(nees < 5.99):.3f}")
    for lo, hi in [(0, 2500), (2500, 3000), (3000, 3500), (3500, 1e9)]:
        m = (alt >= lo) & (alt < hi)
        if m.any():
            band = f"{lo}-{hi} m" if hi < 1e9 else f"above {lo} m"
            print(f"  height {band}: {m.sum()} fixes, mean NEES {nees[m].mean():.2f}")
    q = np.quantile(trace, [0, 0.25, 0.5, 0.75, 1])
    cells = []
    for i in range(4):
        m = (trace >= q[i]) & (trace <= q[i + 1])
        cells.append(f"{trace[m].mean():.2f} -> {err2[m].mean():.2f}")
    print("  claimed variance (east + north, m²) -> mean squared error, by quartile:", "; ".join(cells))
    # The filter's NEES by fifth of each run's flight.
    runs = {}
    for r in rows:
        runs.setdefault(r["run"], []).append(r)
    frac, fn = [], []
    for rs in runs.values():
        t_end = num(rs[-1], "t_s")
        for r in rs:
            n = num(r, "nees")
            if not np.isnan(n):
                frac.append(num(r, "t_s") / t_end)
                fn.append(n)
    frac, fn = np.array(frac), np.array(fn)
    inb = (fn > 0.05) & (fn < 7.38)
    cells = []
    for k in range(5):
        m = (frac >= k / 5) & (frac < (k + 1) / 5 + (k == 4))
        cells.append(f"{inb[m].mean() * 100:.1f} %")
    print(f"  filter NEES in band {inb.mean() * 100:.1f} %; by fifth of the flight:", ", ".join(cells))


for p in sys.argv[1:]:
    report(p)
