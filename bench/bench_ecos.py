"""Benchmark: the seed 000 SSP through the project's master and through Ecos's engine.

Run: python bench/bench_ecos.py [--steps 50000 200000] [--repeats 3] [--csv]

The SSP is the one ``pendulum-cosim export-ssp seed000_cartpole`` writes (FMI 2.0; six
FMUs: the cart-pole plant, the EKF and MF-IAE estimators, the force source, the process
noise and the sensor), run for N communication steps of 10 ms:

* the master: ``cosim.ssp.open_ssp`` and a run recording every signal (31 columns, a row
  per step, returned as a DataFrame), and one recording a single signal (the nearest to
  Ecos recording nothing); its loop time (``timings["loop"]``) and the wall time of
  opening and running;
* Ecos (pip ``ecospy`` 0.7.2, its ``ecos simulate`` command): ``--noCsv`` (records nothing)
  with its parallel stepping and with ``--noParallel``; its loop time is the one it reports
  ("simulated T s in X s"), beside the wall time of its process (which also loads the
  SSP). ``--csv`` adds one Ecos run that writes every signal to its CSV file (what the
  master's recording compares with).

The ratio master / Ecos is of the loop times, medians of the repeats, interleaved, all in
this run. Ecos is installed here in a virtual environment of its own, in the user cache
(``$XDG_CACHE_HOME/pendulum-cosim/bench-ecos``), with pip; its library needs the system's
TBB runtime (Debian: ``apt-get install libtbb12``, which this script does not do). Where
either is missing, the script says so and stops.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.cli import main as cli
from cosim.ssp import open_ssp

H = 0.01
ECOSPY = "ecospy==0.7.2"
#: what Ecos says at the end of a run: "simulated 500.000s in 0.707s"
DONE = re.compile(r"simulated ([0-9.]+)s in ([0-9.]+)s")


def ecos_binary() -> tuple[Path | None, str]:
    """The ``ecos`` program of ecospy, installed in a venv of its own (created on first
    use), or None and why not."""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pendulum-cosim" / "bench-ecos"
    python = cache / "bin" / "python"
    if not python.exists():
        made = subprocess.run([sys.executable, "-m", "venv", str(cache)], capture_output=True, text=True)
        if made.returncode != 0:
            return None, f"no virtual environment could be made in {cache}: {made.stderr.strip()[-300:]}"
    where = subprocess.run([str(python), "-c", "import ecospy, os; print(os.path.dirname(ecospy.__file__))"],
                           capture_output=True, text=True)
    if where.returncode != 0:
        pip = subprocess.run([str(python), "-m", "pip", "install", "-q", ECOSPY], capture_output=True, text=True)
        if pip.returncode != 0:
            return None, f"pip could not install {ECOSPY}: {pip.stderr.strip()[-300:]}"
        where = subprocess.run(where.args, capture_output=True, text=True)
    binary = Path(where.stdout.strip()) / "binaries" / "ecos"
    if not binary.exists():
        return None, f"{ECOSPY} has no Linux program at {binary}"
    binary.chmod(0o755)                         # the wheel ships it without the executable bit
    (binary.parent / "proxyfmu").chmod(0o755)
    missing = [line.split()[0] for line in subprocess.run(["ldd", str(binary)], capture_output=True,
                                                           text=True).stdout.splitlines() if "not found" in line]
    if missing:
        return None, f"Ecos needs {', '.join(missing)} (the TBB runtime; Debian: apt-get install libtbb12)"
    return binary, ""


def ecos_run(binary: Path, ssp: Path, steps: int, *flags: str) -> tuple[float, float]:
    """(loop time Ecos reports, wall time of its process) [s] of ``steps`` steps."""
    with tempfile.TemporaryDirectory() as cwd:                 # its CSV file, if any, goes there
        t0 = time.perf_counter()
        done = subprocess.run([str(binary), "simulate", "--path", str(ssp), "--stopTime", repr(steps * H),
                               "--stepSize", repr(H), *flags], capture_output=True, text=True, cwd=cwd)
        wall = time.perf_counter() - t0
    said = DONE.findall(done.stdout + done.stderr)
    if done.returncode != 0 or not said:
        raise SystemExit(f"ecos failed ({done.returncode}): {(done.stdout + done.stderr)[-1000:]}")
    return float(said[-1][1]), wall


def master_run(ssp: Path, steps: int, signals=None) -> tuple[float, float, str, int]:
    """(loop time, wall time of opening and running [s], how it stepped, recorded columns)."""
    t0 = time.perf_counter()
    with open_ssp(ssp) as system:
        df = system.cosim.run(steps * H, progress=False, signals=signals)
        timings, stepping = system.cosim.timings, system.cosim.stepping
    return timings["loop"], time.perf_counter() - t0, stepping, df.shape[1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, nargs="+", default=[50_000, 200_000], help="steps of 10 ms")
    ap.add_argument("--repeats", type=int, default=3, help="repeats, interleaved (default 3)")
    ap.add_argument("--csv", action="store_true", help="also one Ecos run writing its CSV file")
    args = ap.parse_args(argv)
    binary, why = ecos_binary()
    if binary is None:
        print(f"bench_ecos: skipped: {why}")
        return
    print(f"{os.cpu_count()} cores; load average {os.getloadavg()[0]:.2f} at the start")
    with tempfile.TemporaryDirectory() as tmp:
        if cli(["export-ssp", "seed000_cartpole", "--out", str(Path(tmp) / "ssp")]) != 0:
            raise SystemExit("export-ssp failed")
        ssp = next((Path(tmp) / "ssp").glob("*.ssp"))
        master_run(ssp, 100)                                   # the FMUs' libraries, the kernel: loaded once
        kinds = {"master (records all)": lambda n: master_run(ssp, n)[:2],
                 "master (records plant.x)": lambda n: master_run(ssp, n, ["plant.x"])[:2],
                 "Ecos --noCsv": lambda n: ecos_run(binary, ssp, n, "--noCsv"),
                 "Ecos --noCsv --noParallel": lambda n: ecos_run(binary, ssp, n, "--noCsv", "--noParallel")}
        for steps in args.steps:
            times: dict[str, list] = {k: [] for k in kinds}
            for _ in range(args.repeats):
                for kind, fn in kinds.items():
                    times[kind].append(fn(steps))
            med = {k: np.median(np.array(v), axis=0) for k, v in times.items()}
            _, _, stepping, columns = master_run(ssp, 100)
            print(f"\n{steps} steps of {H:g} s, medians of {args.repeats} (loop; wall of open + run / of the process):")
            for kind, (loop, wall) in med.items():
                print(f"  {kind:28s} loop {loop:7.3f} s ({loop / steps * 1e6:6.2f} µs/step)   wall {wall:7.3f} s")
            if args.csv:
                loop, wall = ecos_run(binary, ssp, steps)
                print(f"  {'Ecos, CSV of every signal':28s} loop {loop:7.3f} s ({loop / steps * 1e6:6.2f} µs/step)"
                      f"   wall {wall:7.3f} s (one run)")
            m = med["master (records all)"][0]
            print(f"  master / Ecos (loop): {m / med['Ecos --noCsv'][0]:.2f}x; master / Ecos --noParallel: "
                  f"{m / med['Ecos --noCsv --noParallel'][0]:.2f}x; the master recorded {columns} columns every "
                  f"step, Ecos nothing; the master stepped {stepping}")
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
