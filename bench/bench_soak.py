"""Soak benchmark: the project's FMUs under the call-sequence fuzzer for a given time, or for a
given number of sequences. Measured, not asserted.

Run: python bench/bench_soak.py --fuzz-seconds 600 [--jobs 2] [--seed 1]
     python bench/bench_soak.py --fuzz-sequences 100000      (per FMU kind and FMI version)
     python bench/bench_soak.py --parts chaos --chaos-runs 10000

Part "fuzz": every FMU kind (plant: cartpole and iwp; estimator: EKF and MF-IAE; signal: PRBS
and sensor; clocked: the clocked EKF and sensor, FMI 3.0 only), FMI 2.0 and 3.0,
rebuilt from its own ``sources/`` with AddressSanitizer and
UndefinedBehaviorSanitizer (tests/testkit/fuzz_run.py), driven by tests/data/fuzz/fuzz.c in
chunks of seeded sequences. Reported per kind and version: sequences, calls, illegal calls and
how many were answered Error, legal calls and how many OK, sanitizer reports, crashes, hangs,
state-machine violations, and the replay command of every failing sequence.

Part "chaos": the co-simulation master against the chaos FMU (tests/data/chaos: every call
may return Warning, Discard, Error or Fatal, give NaN or inf outputs or sleep, by seed), for
a number of runs or a time; each run must end normally with finite results, or with a named
error (the FMU, the FMI call or the signal, the time) that keeps its rows, and the FMU's log
must show no call the standard forbids (tests/testkit/chaos.py). Reported: runs, outcomes
by class, failures (a broken rule, a bare exception), and the seeds that failed.

The parts are listed in PARTS (name -> function(args) -> report lines); each runs when asked
for with --parts (default: all).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cosim  # noqa: F401 - the real packages before tests/ is on the path
import estimators  # noqa: F401
import fmu_models  # noqa: F401

sys.path.append(str(Path(__file__).parents[1] / "tests"))   # the fuzzer's helpers (tests/testkit)
from testkit import fuzz_run  # after the path

COUNTS = ("sequences", "calls", "illegal", "illegal_error", "legal", "legal_ok")
FAILURES = ("sanitizer", "crash", "hang", "violation")


def _fuzz_target(t, seed: int, budget_s: float | None, sequences: int | None, chunk: int) -> dict:
    """Run chunks on one target until the time budget or the sequence count is spent."""
    tot = dict.fromkeys(COUNTS + FAILURES, 0)
    tot["replays"] = []
    first, t0 = 0, time.perf_counter()
    while True:
        if sequences is not None and first >= sequences:
            break
        if budget_s is not None and time.perf_counter() - t0 >= budget_s:
            break
        n = chunk if sequences is None else min(chunk, sequences - first)
        r = fuzz_run.run(t, seed, first, n)
        for k in COUNTS:
            tot[k] += int(r.counts.get(k, 0) or 0)
        if r.outcome == "ok":
            first += n
            continue
        tot[r.outcome] += 1
        seq = _failing_sequence(r.report)
        head = next((ln for ln in r.report.splitlines() if ln.strip()), "")
        tot["replays"].append(f"{r.outcome} ({head[:300]}): "
                              f"{fuzz_run.replay_command(t, seed, seq if seq is not None else first)}")
        # go on after the failing sequence (its chunk's later sequences included)
        first = (seq + 1) if seq is not None else first + n
    tot["seconds"] = time.perf_counter() - t0
    return tot


def _failing_sequence(report: str) -> int | None:
    import re

    m = re.search(r"^(?:VIOLATION|HANG|DIED) seed=\d+ seq=(\d+)", report, re.M)
    return int(m.group(1)) if m else None


def fuzz_part(args) -> list[str]:
    """The fuzzer over every FMU kind and FMI version; the report lines."""
    versions = [int(v) for v in args.versions.split(",")]
    labels = [(kind, label) for kind, ls in fuzz_run.FMU_KINDS.items() for label in ls
              if kind in args.kinds.split(",")]
    with tempfile.TemporaryDirectory(prefix="pendulum_soak_") as tmp:
        targets = []
        for kind, label in labels:
            for v in versions:
                if v == 2 and kind in fuzz_run.FMI3_ONLY:     # the clocked form has no FMI 2.0
                    continue
                fmu = fuzz_run.build_fmu_for(label, v, Path(tmp) / "fmus")
                targets.append((kind, label, v, fuzz_run.build_target(fmu, Path(tmp) / "build")))
        per_kind = {}
        for kind, label, _, _ in targets:
            per_kind[kind] = per_kind.get(kind, set()) | {label}
        budget = None if args.fuzz_seconds is None else args.fuzz_seconds * args.jobs / len(targets)
        seqs = {(k, lb, v): None if args.fuzz_sequences is None else -(-args.fuzz_sequences // len(per_kind[k]))
                for k, lb, v, _ in targets}
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            futures = {(k, lb, v): pool.submit(_fuzz_target, t, args.seed, budget, seqs[k, lb, v], args.chunk)
                       for k, lb, v, t in targets}
            results = {key: f.result() for key, f in futures.items()}
    lines = ["| FMU kind | FMI | FMUs | sequences | calls | illegal calls answered Error | "
             "legal calls answered OK | sanitizer reports | crashes | hangs | violations | seq/s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    replays = []
    for kind in dict.fromkeys(k for k, _, _, _ in targets):
        for v in versions:
            rows = [r for (k, _, vv), r in results.items() if k == kind and vv == v]
            if not rows:                                # a kind without this FMI version (clocked: 3.0 only)
                continue
            s = {c: sum(r[c] for r in rows) for c in COUNTS + FAILURES}
            secs = max(r["seconds"] for r in rows)
            lines.append(f"| {kind} | {v}.0 | {', '.join(sorted(per_kind[kind]))} | {s['sequences']} | {s['calls']} | "
                         f"{s['illegal_error']} / {s['illegal']} | {s['legal_ok']} / {s['legal']} | "
                         f"{s['sanitizer']} | {s['crash']} | {s['hang']} | {s['violation']} | "
                         f"{s['sequences'] / secs:.0f} |")
            replays += [x for r in rows for x in r["replays"]]
    lines.append("")
    lines += [f"failing sequence: {x}" for x in replays] or ["no failing sequence"]
    return lines


#: The parts of the soak benchmark, by name.
def chaos_part(args) -> list[str]:
    """The master against the chaos FMU over many seeds; the report lines."""
    import collections
    import logging
    import os

    from testkit import chaos, handwritten

    outcomes, failures = collections.Counter(), []
    with tempfile.TemporaryDirectory(prefix="pendulum_soak_chaos_") as tmp:
        fmu = handwritten.build("chaos", "Chaos", 2, Path(tmp) / "fmu")
        log = Path(tmp) / "chaos.log"
        os.environ["CHAOS_LOG"] = str(log)
        logging.getLogger("cosim.fmu").setLevel(logging.CRITICAL + 1)     # the FMU's own chatter, by the thousand
        t0, seed = time.perf_counter(), 0
        while (seed < args.chaos_runs if args.chaos_seconds is None
               else time.perf_counter() - t0 < args.chaos_seconds):
            rate = 0.005 + 0.02 * (seed % 5) / 4            # 0.5 % to 2.5 % of the calls misbehave
            try:
                outcomes[chaos.run_seed(fmu, args.seed * 1_000_003 + seed, rate, chaos.NO_CRASH, log)] += 1
            except AssertionError as e:                    # a rule of the run broken
                failures.append(f"seed {seed}: {e}")
            except Exception as e:  # noqa: BLE001 - a bare exception out of the master is a failure too
                failures.append(f"seed {seed}: {type(e).__name__}: {e}")
            seed += 1
        wall = time.perf_counter() - t0
    lines = [f"runs: {seed} in {wall:.0f} s ({wall / max(seed, 1) * 1e3:.1f} ms a run)",
             "outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())),
             f"failures (a broken rule or a bare exception): {len(failures)}"]
    return lines + failures[:20]


PARTS = {"fuzz": fuzz_part, "chaos": chaos_part}


def main(argv: list[str] | None = None) -> None:
    """Command line (see the module documentation)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fuzz-seconds", type=float, default=None, help="time for the fuzz part [s] (default 60)")
    p.add_argument("--fuzz-sequences", type=int, default=None,
                   help="sequences per FMU kind and FMI version instead of a time")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--jobs", type=int, default=1, help="driver processes at once")
    p.add_argument("--chunk", type=int, default=2000, help="sequences per driver process")
    p.add_argument("--kinds", default="plant,estimator,signal,clocked")
    p.add_argument("--versions", default="2,3")
    p.add_argument("--chaos-runs", type=int, default=1000, help="runs of the chaos part (default 1000)")
    p.add_argument("--chaos-seconds", type=float, default=None, help="time for the chaos part instead [s]")
    p.add_argument("--parts", default=",".join(PARTS))
    args = p.parse_args(argv)
    if args.fuzz_seconds is None and args.fuzz_sequences is None:
        args.fuzz_seconds = 60.0
    for name in args.parts.split(","):
        if name not in PARTS:
            p.error(f"unknown part {name!r} (parts: {', '.join(PARTS)})")
    print("command: python bench/bench_soak.py " + " ".join(sys.argv[1:] if argv is None else argv))
    for name in args.parts.split(","):
        t0 = time.perf_counter()
        print(f"\n## {name}\n")
        print("\n".join(PARTS[name](args)))
        print(f"\n({name}: {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
