"""Benchmark: the full seed-000 campaign (4 scenarios x 100 realisations x every filter of
the campaign x 500 steps, one noise reading) on the fast path and through the FMU master, on
this machine's cores.

Run: python bench/bench_campaign.py [--skip-master] [--write-docs]
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cosim.experiments import seed000

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-master", action="store_true")
    doc_tables.add_option(ap)
    args = ap.parse_args()
    s = seed000.Settings()
    seed000.run(seed000.Settings(runs=2, duration=0.1), readings=("eqs",), progress=False)  # warm cache
    print(f"{os.cpu_count()} cores; 4 scenarios x {s.runs} realisations x {len(seed000.FILTERS)} filters "
          f"({', '.join(seed000.FILTERS)}) x {s.steps} steps")
    figures = {"runs": s.runs, "filters": list(seed000.FILTERS), "steps": s.steps, "wall_s": {}}
    for path in ("fast",) + (() if args.skip_master else ("master",)):
        wall = seed000.run(s, path=path, readings=("eqs",), progress=False).wall
        figures["wall_s"][path] = wall
        print(f"{path:6s} path: {wall:6.2f} s")
    if args.write_docs:
        doc_tables.write_docs(__file__, figures)


def campaign_table(saved) -> str:
    """The performance page's table: the seed 000 campaign's wall time on both paths."""
    f = saved["bench_campaign"]["figures"]
    wall = f["wall_s"]
    what = f"4 scenarios x {f['runs']} realisations x {len(f['filters'])} filters x {f['steps']} steps"
    return doc_tables.with_provenance(saved, "bench_campaign", doc_tables.table(
        ["seed 000 campaign, one reading", "fast path", "FMU master path", "master / fast"],
        [[what, f"{wall['fast']:.2f} s", f"{wall['master']:.2f} s", f"{wall['master'] / wall['fast']:.2f}x"]]))


TABLES = {"campaign": campaign_table}


if __name__ == "__main__":
    main()
