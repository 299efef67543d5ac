#!/usr/bin/env python3
"""Pool the correct fixes of many `ground-sim eval --csv` campaigns and score their σ.

Each argument is LABEL=CSV; campaigns with the same label are pooled. For each label: the
campaigns, fixes and false fixes, the pooled mean NEES (2 dof; 2 if the σ is right), the share
under the 95 % point (5.99), the share within 3σ (11.83) and the campaigns' mean-NEES range.
One 4 km campaign is one draw of its map's error; pooled many, they test a σ model
(docs/registration.md, "The map's slope noise against its slope signal", session 47).

    python3 tools/pool_nees.py plains-default=p11.csv plains-default=p12.csv lola-default=l11.csv
"""
import csv
import sys
from collections import defaultdict

pools = defaultdict(list)
for arg in sys.argv[1:]:
    label, sep, path = arg.partition("=")
    if not sep or not path:
        sys.exit(f"expected LABEL=CSV, got {arg!r}")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and "nees" not in rows[0]:
        sys.exit(f"{path}: not an eval CSV (no nees column)")
    pools[label].append(rows)
if not pools:
    sys.exit(__doc__)

print("| pool | campaigns | fixes of frames | false fixes | mean NEES | under 5.99 | under 11.83 | campaigns' mean NEES |")
print("|---|---|---|---|---|---|---|---|")
for label, campaigns in pools.items():
    nees, means, fixes, frames, false = [], [], 0, 0, 0
    for rows in campaigns:
        frames += len(rows)
        fixes += sum(r["fix"] == "true" for r in rows)
        false += sum(r["false_fix"] == "true" for r in rows)
        n = [float(r["nees"]) for r in rows
             if r["fix"] == "true" and r["false_fix"] == "false" and r["nees"]]
        nees += n
        if n:
            means.append(sum(n) / len(n))
    if not nees:
        print(f"| {label} | {len(campaigns)} | {fixes} of {frames} | {false} | – | – | – | – |")
        continue
    share = lambda t: 100.0 * sum(v < t for v in nees) / len(nees)
    print(f"| {label} | {len(campaigns)} | {fixes} of {frames} | {false} | {sum(nees) / len(nees):.2f} "
          f"| {share(5.991):.1f} % | {share(11.83):.1f} % | {min(means):.2f}–{max(means):.2f} |")
