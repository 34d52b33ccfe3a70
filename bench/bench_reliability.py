"""Reliability figures for the reliability page: measured, not asserted.

Run: python bench/bench_reliability.py [--trials 20]

* cold cache: ``--trials`` times, 8 processes build the same filter into one empty cache at
  once; counts failed processes and checks that all got the same numbers;
* damaged cache: a cached library truncated, emptied or overwritten; the next run warns,
  rebuilds and gets the same numbers (runs needed until a clean run);
* interruption: a master-path seed 000 campaign on 2 workers gets SIGINT or SIGTERM 3 s
  after it started; time from the signal to the exit, exit status, partial summary, and
  worker processes left;
* temporary folders: count of ``pendulum_cosim_*`` folders in the temp folder before and
  after 100 runs of a plant FMU through the master.
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]
PROBE = ("import warnings; warnings.simplefilter('always'); "
         "from estimators import EKF, discretize; from fmu_models import get_model; "
         "f = EKF(discretize(get_model('cartpole'), 0.01), [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1); "
         "print(f.backend, repr(float(f.step([0.1], [0.5, 1.8])[2])))")
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


def probe(cache: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", PROBE], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, env={**os.environ, "PENDULUM_COSIM_CACHE": str(cache)})


def cold_cache(trials: int) -> None:
    failures, outputs, walls = 0, set(), []
    for _ in range(trials):
        with tempfile.TemporaryDirectory() as cache:
            t0 = time.perf_counter()
            procs = [probe(Path(cache)) for _ in range(8)]
            for p in procs:
                out, _ = p.communicate()
                failures += p.returncode != 0
                outputs.add(out)
            walls.append(time.perf_counter() - t0)
    print(f"cold cache: {trials} trials x 8 processes: {failures} failed, {len(outputs)} distinct result(s), "
          f"{sum(walls) / len(walls):.1f} s per trial")


def damaged_cache() -> None:
    for damage in ("truncate", "empty", "garbage"):
        with tempfile.TemporaryDirectory() as cache:
            cache = Path(cache)
            good, _ = probe(cache).communicate()
            for lib in cache.glob("*.so"):
                data = lib.read_bytes()
                lib.write_bytes({"truncate": data[: len(data) // 3], "empty": b"",
                                 "garbage": os.urandom(len(data))}[damage])
            runs = 0
            while True:
                runs += 1
                out, err = probe(cache).communicate()
                if "damaged" not in err:
                    break
            print(f"damaged cache ({damage}): same result {out == good}, clean after {runs - 1} repairing run(s)")


def interruption(repeats: int) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        delays = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "out"
                p = subprocess.Popen([*CLI, "experiment", "seed000", "--path", "master", "--runs", "200",
                                      "--jobs", "2", "--quiet", "--out", str(out)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                while not out.exists():
                    time.sleep(0.02)
                time.sleep(3.0)
                t0 = time.perf_counter()
                p.send_signal(sig)
                p.wait()
                delays.append(time.perf_counter() - t0)
                partial = (out / "summary.md").exists() and "partial" in (out / "summary.md").read_text().lower()
                left = [d for d in Path("/proc").glob("[0-9]*")
                        if str(out) in (d / "cmdline").read_bytes().decode(errors="replace")] \
                    if Path("/proc").exists() else []
                assert p.returncode == 130 and partial and not left, (p.returncode, partial, left)
        print(f"interruption ({sig.name}): exit 130 with partial results, no worker left, in "
              f"{min(delays):.2f}-{max(delays):.2f} s after the signal ({repeats} runs)")


def temp_folders() -> None:
    from cosim.components.sources import Constant
    from cosim.core.master import Cosimulation
    from cosim.fmi.fmu_component import FMUComponent
    from fmu_models import build_fmu

    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_fmu("cartpole", tmp)
        cosim = Cosimulation([FMUComponent("p", fmu, 0.01), Constant("f", 0.01, 0.1)], {"p.F": "f.out"})
        count = lambda: len(list(Path(tempfile.gettempdir()).glob("pendulum_cosim_*")))  # noqa: E731
        before = count()
        for _ in range(100):
            cosim.run(0.05)
        print(f"temporary folders: {before} before, {count()} after 100 runs")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="cold-cache trials (default 20)")
    parser.add_argument("--repeats", type=int, default=3, help="interruptions per signal (default 3)")
    args = parser.parse_args()
    cold_cache(args.trials)
    damaged_cache()
    interruption(args.repeats)
    temp_folders()


if __name__ == "__main__":
    main()
