"""Benchmark and check: cross-built FMU binaries (issue 19).

For both plants and the EKF FMU in FMI 2.0 and 3.0: the time ``add_platforms`` adds for
win64, darwin and aarch64-linux with zig's own cache warm but an empty compiled-code cache
(what a user pays for a changed model), and the largest difference between the outputs of
the Windows (wine) and aarch64-linux (qemu-user) binaries and those of linux64 over 100
steps of the FMI driver tests/data/cross_harness/harness.c.

Run: python bench/bench_platforms.py     (needs pip install -e '.[cross]', wine64, qemu-user)
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from estimators import EKF, discretize
from estimators.filter_fmu import export_filter_fmu
from fmu_models import build_fmu, get_model
from fmu_models.export.platforms import add_platforms

sys.path.append(str(Path(__file__).parents[1] / "tests"))     # the driver helpers (tests/testkit/cross_run.py),
from testkit import cross_run  # after the packages (tests/estimators is no package)

PLATFORMS = ["win64", "darwin", "aarch64-linux"]


def main() -> None:
    cp = discretize(get_model("cartpole"), 0.01)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # warm zig's cache once (its C runtimes), outside the timing
        add_platforms(build_fmu("cartpole", tmp / "warm", 3), PLATFORMS)
        os.environ["PENDULUM_COSIM_CACHE"] = str(tmp / "empty-cache")   # no cached binaries of ours
        print("| FMU | FMI | native build [s] | + win64, darwin, aarch64-linux [s] | win64 max abs diff | "
              "aarch64-linux max abs diff |")
        print("|---|---|---|---|---|---|")
        for name in ("cartpole", "iwp", "ekf"):
            for v in (2, 3):
                out = tmp / f"{name}{v}"
                t0 = time.perf_counter()
                fmu = (export_filter_fmu(EKF(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1), out, fmi_version=v, name="ekf")
                       if name == "ekf" else build_fmu(name, out, fmi_version=v))
                t1 = time.perf_counter()
                add_platforms(fmu, PLATFORMS)
                t2 = time.perf_counter()
                diffs = []
                for plat in ("win64", "aarch64-linux"):
                    if (v, plat) not in cross_run.FOLDERS:
                        diffs.append("(no FMI 2.0 folder)")
                        continue
                    ref, got = cross_run.compare(fmu, v, plat, tmp)
                    diffs.append(f"{np.abs(got - ref).max():.1e} (max |y| {np.abs(ref).max():.2g})")
                print(f"| {name} | {v}.0 | {t1 - t0:.2f} | {t2 - t1:.2f} | {diffs[0]} | {diffs[1]} |")


if __name__ == "__main__":
    main()
