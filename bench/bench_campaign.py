"""Benchmark: the full seed-000 campaign (4 scenarios x 100 realisations x every filter of
the campaign x 500 steps, one noise reading) on the fast path and through the FMU master, on
this machine's cores.

Run: python bench/bench_campaign.py [--skip-master]
"""
from __future__ import annotations

import argparse
import os

from cosim.experiments import seed000


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-master", action="store_true")
    args = ap.parse_args()
    s = seed000.Settings()
    seed000.run(seed000.Settings(runs=2, duration=0.1), readings=("eqs",), progress=False)  # warm cache
    print(f"{os.cpu_count()} cores; 4 scenarios x {s.runs} realisations x {len(seed000.FILTERS)} filters "
          f"({', '.join(seed000.FILTERS)}) x {s.steps} steps")
    for path in ("fast",) + (() if args.skip_master else ("master",)):
        wall = seed000.run(s, path=path, readings=("eqs",), progress=False).wall
        print(f"{path:6s} path: {wall:6.2f} s")


if __name__ == "__main__":
    main()
