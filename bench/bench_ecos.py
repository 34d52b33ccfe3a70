"""Benchmark: the seed 000 SSP through the project's master and through Ecos's engine.

Run: python bench/bench_ecos.py [--steps 50000 200000] [--repeats 3] [--write-docs]

The SSP is the one ``pendulum-cosim export-ssp seed000_cartpole`` writes (FMI 2.0; six
FMUs: the cart-pole plant, the EKF and MF-IAE estimators, the force source, the process
noise and the sensor), run for N communication steps of 10 ms:

* the master: ``cosim.ssp.open_ssp`` and a run recording nothing (``signals=[]``: the
  FMUs' outputs that no input takes are not read), and one recording every signal (31
  columns, a row per step, returned as a DataFrame); its loop time (``timings["loop"]``)
  and the wall time of opening and running;
* Ecos (pip ``ecospy`` 0.7.2, its ``ecos simulate`` command): ``--noCsv`` (records nothing)
  with its parallel stepping and with ``--noParallel``, and a run writing every signal to
  its CSV file; its loop time is the one it reports ("simulated T s in X s"), beside the
  wall time of its process (which also loads the SSP).

The ratios master / Ecos compare like with like (nothing recorded; every signal recorded),
of the loop times, medians of the repeats, interleaved, all in this run. Ecos is installed
here in a virtual environment of its own, in the user cache
(``$XDG_CACHE_HOME/pendulum-cosim/bench-ecos``), with pip; its library needs the system's
TBB runtime (Debian: ``apt-get install libtbb12``, which this script does not do). Where
either is missing, the script says so and stops. The master runs with its default
``threads="auto"`` (what it chose is printed). ``--write-docs`` saves the figures and
rewrites the performance page's table (``bench/doc_tables.py``).
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

sys.path.append(str(Path(__file__).parent))          # bench/doc_tables.py, from any folder
import doc_tables  # after the path

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


KINDS = ("master, nothing recorded", "master, every signal", "Ecos --noCsv", "Ecos --noCsv --noParallel",
         "Ecos, CSV of every signal")


def measure(ssp: Path, binary: Path, steps: int, repeats: int) -> dict:
    """One number of steps, printed: per kind, the medians [loop, wall] (s), and how the
    master stepped."""
    fns = (lambda n: master_run(ssp, n, [])[:2], lambda n: master_run(ssp, n)[:2],
           lambda n: ecos_run(binary, ssp, n, "--noCsv"), lambda n: ecos_run(binary, ssp, n, "--noCsv", "--noParallel"),
           lambda n: ecos_run(binary, ssp, n))
    times: dict[str, list] = {k: [] for k in KINDS}
    for _ in range(repeats):
        for kind, fn in zip(KINDS, fns):
            times[kind].append(fn(steps))
    med = {k: np.median(np.array(v), axis=0).tolist() for k, v in times.items()}
    _, _, stepping, columns = master_run(ssp, steps)
    print(f"\n{steps} steps of {H:g} s, medians of {repeats} (loop; wall of open + run / of the process):")
    for kind, (loop, wall) in med.items():
        print(f"  {kind:28s} loop {loop:7.3f} s ({loop / steps * 1e6:6.2f} µs/step)   wall {wall:7.3f} s")
    print(f"  master / Ecos (loop), nothing recorded: {med[KINDS[0]][0] / med[KINDS[2]][0]:.2f}x "
          f"(Ecos --noParallel: {med[KINDS[0]][0] / med[KINDS[3]][0]:.2f}x); every signal recorded "
          f"({columns} columns): {med[KINDS[1]][0] / med[KINDS[4]][0]:.2f}x; the master stepped {stepping}")
    return {"steps": steps, "median": med, "stepping": stepping, "columns": columns}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, nargs="+", default=[50_000, 200_000], help="steps of 10 ms")
    ap.add_argument("--repeats", type=int, default=3, help="repeats, interleaved (default 3)")
    doc_tables.add_option(ap)
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
        rows = [measure(ssp, binary, steps, args.repeats) for steps in args.steps]
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    if args.write_docs:
        doc_tables.write_docs(__file__, {"ecos": ECOSPY, "rows": rows})


def ecos_table(saved) -> str:
    """The performance page's table: loop times of the master and of Ecos, and their ratios."""
    f = saved["bench_ecos"]["figures"]
    rows = []
    for r in f["rows"]:
        med, steps = r["median"], r["steps"]
        rows.append([f"{steps:,}".replace(",", " ")] + [f"{med[k][0]:.3f} s" for k in KINDS]
                    + [f"{med[KINDS[0]][0] / med[KINDS[2]][0]:.2f}x", f"{med[KINDS[1]][0] / med[KINDS[4]][0]:.2f}x"])
    head = ["steps of 10 ms", "master, nothing recorded", "master, every signal", "Ecos `--noCsv`",
            "Ecos `--noCsv --noParallel`", "Ecos, CSV of every signal", "master / Ecos, nothing recorded",
            "master / Ecos, every signal"]
    return doc_tables.with_provenance(saved, "bench_ecos", doc_tables.table(head, rows))


TABLES = {"ecos": ecos_table}


if __name__ == "__main__":
    main()
