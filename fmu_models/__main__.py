"""``python -m fmu_models build --out DIR [--fmi-version 2] [--model NAME] [--platforms LIST]``:
build the plant FMUs (``--platforms linux64,win64,darwin,aarch64-linux`` adds cross-compiled
binaries, see :mod:`fmu_models.export.platforms`)."""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from .catalog import model_names
from .export.pack import FMI_VERSIONS
from .export.plant_fmu import build_fmus
from .export.platforms import PLATFORMS, add_platforms, parse_platforms, zig_command
from .infra.cli import run_command
from .infra.files import private_tempdir, remove_empty_folders


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m fmu_models``; returns the exit status (0, 2 on an error,
    130 when interrupted)."""
    parser = argparse.ArgumentParser(prog="python -m fmu_models",
                                     description="Build the plant FMUs from the CasADi models.")
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="compile and pack the FMU of every registered plant model")
    b.add_argument("--out", default=".", help="output directory (default: current directory)")
    b.add_argument("--fmi-version", type=int, choices=FMI_VERSIONS, default=2,
                   help="FMI version, 2 (default) or 3; both hold Model Exchange and Co-Simulation")
    b.add_argument("--model", action="append", choices=model_names(),
                   help="build only this model (repeatable; default: all)")
    b.add_argument("--platforms", metavar="LIST",
                   help=f"also build binaries for these platforms (comma-separated: {','.join(PLATFORMS)}); "
                        "needs pip install -e '.[cross]'")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    out = Path(args.out)
    created = [p for p in (out.absolute(), *out.absolute().parents) if not p.exists()]

    def build() -> int:
        notes: list[str] = []
        platforms = parse_platforms(args.platforms)
        models = tuple(args.model or model_names())
        if not platforms:
            paths = build_fmus(args.out, args.fmi_version, models)
        else:                                      # complete FMUs only: built and extended aside, then moved
            zig_command()                          # a missing extra is named before anything is built
            out.mkdir(parents=True, exist_ok=True)
            with private_tempdir(".build-", dir=out) as tmp:
                staged = build_fmus(tmp, args.fmi_version, models)
                for p in staged:
                    notes += add_platforms(p, platforms)
                paths = [out / p.name for p in staged]
                for p, dst in zip(staged, paths):
                    os.replace(p, dst)
        for p in paths:
            print(p)
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
        print(f"built {len(paths)} FMU(s) in {time.perf_counter() - t0:.2f} s", file=sys.stderr)
        return 0

    return run_command(build, cleanup=lambda: remove_empty_folders(created),
                       interrupted="interrupted: no FMU was left half-written")


if __name__ == "__main__":
    sys.exit(main())
