"""The tables of measured figures on the documentation pages and in the README, written by
the benchmark scripts that measure them.

A table on a page stands between two marker lines (HTML comments: invisible on GitHub and
in the built pages) naming the script and the table::

    <!-- table: bench/bench_master.py master -->
    | ... |
    <!-- /table -->

A script that writes tables defines ``TABLES``: table name -> function(saved) -> Markdown,
where ``saved[stem]`` is what the last run of ``bench/<stem>.py`` saved in
``bench/figures/<stem>.json`` (``"figures"``, and ``"run"``: when, where and on what it
ran). ``python bench/<stem>.py --write-docs`` measures, saves its figures, and rewrites
every table block of the pages from the saved figures; ``python bench/doc_tables.py``
rewrites them without measuring anything; tests/test_doc_tables.py checks that every block
is what its script makes of the saved figures.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import runpy
import subprocess
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "bench" / "figures"
_BLOCK = re.compile(r"^<!-- table: (?P<script>bench/\w+\.py) (?P<name>[\w-]+) -->\n(?P<body>.*?)^<!-- /table -->$",
                    re.M | re.S)
#: What a measurement depends on: a run with changes to these that are not committed says so.
CODE = ("fmu_models", "estimators", "cosim", "bench", "tests", "pyproject.toml")
_OPEN = re.compile(r"^<!-- (?:table: .*|/table) -->$", re.M)


@dataclass(frozen=True)
class Block:
    """One table block of a page: ``script`` (relative to the repository), ``name``,
    ``body`` (the text between the markers) and its ``span`` in the page's text."""

    page: Path
    script: str
    name: str
    body: str
    span: tuple[int, int]


def _name(page: Path) -> str:
    """``page`` relative to the repository where it is in it."""
    return str(page.relative_to(ROOT)) if page.is_relative_to(ROOT) else str(page)


def pages() -> list[Path]:
    """The README and every Markdown page of ``docs/`` (not the build folder)."""
    return [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)]


def blocks(page: Path) -> list[Block]:
    """The table blocks of ``page``; a marker line outside a well-formed block is an error."""
    text = page.read_text(encoding="utf-8")
    found = [Block(page, m["script"], m["name"], m["body"], m.span("body")) for m in _BLOCK.finditer(text)]
    markers = len(_OPEN.findall(text))
    if markers != 2 * len(found):
        raise ValueError(f"{_name(page)}: {markers} table markers but {len(found)} well-formed blocks "
                         "(<!-- table: bench/SCRIPT.py NAME --> ... <!-- /table -->, each on a line of its own)")
    return found


class Saved(Mapping):
    """The saved figures of every script, read when first asked for: ``saved["bench_master"]``."""

    def __init__(self, folder: Path | None = None):
        self.folder = folder or FIGURES
        self._cache: dict[str, dict] = {}

    def __getitem__(self, stem: str) -> dict:
        if stem not in self._cache:
            path = self.folder / f"{stem}.json"
            if not path.exists():
                raise KeyError(f"no saved figures of bench/{stem}.py ({_name(path)}): run "
                               f"python bench/{stem}.py --write-docs")
            self._cache[stem] = json.loads(path.read_text())
        return self._cache[stem]

    def __iter__(self):
        return iter(sorted(p.stem for p in self.folder.glob("*.json")))

    def __len__(self) -> int:
        return len(list(self.folder.glob("*.json")))


@cache
def tables_of(script: str) -> Mapping[str, Callable]:
    """The ``TABLES`` of ``script`` (its module level run, not its main)."""
    return runpy.run_path(str(ROOT / script), run_name="bench_tables").get("TABLES", {})


def render(block: Block, saved: Mapping) -> str:
    """What ``block`` must hold: its script's table made from the saved figures."""
    tables = tables_of(block.script)
    if block.name not in tables:
        raise KeyError(f"{_name(block.page)}: {block.script} has no table {block.name!r} "
                       f"(it has {sorted(tables)})")
    return tables[block.name](saved).strip("\n") + "\n"


def table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table."""
    return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
                      *("| " + " | ".join(row) + " |" for row in rows)])


def with_provenance(saved: Mapping, stem: str, *tables: str) -> str:
    """``tables`` and, under them, when, where and how ``bench/<stem>.py`` measured them."""
    return "\n\n".join([*tables, provenance(saved, stem)])


def run_info() -> dict:
    """When, where and on what a benchmark ran: the date, the commit, the machine, the versions."""
    commit = _git("rev-parse", "--short", "HEAD")
    if commit and _git("status", "--porcelain", "--untracked-files=no", "--", *CODE, ":!bench/figures"):
        commit += " with uncommitted changes"        # to the code: the pages and figures do not count
    versions = {}
    for name in ("numpy", "casadi", "fmpy"):
        module = sys.modules.get(name)
        if module is not None:
            versions[name] = getattr(module, "__version__", "?")
    cpu = next((line.split(":", 1)[1].strip() for line in _read("/proc/cpuinfo").splitlines()
                if line.startswith("model name")), platform.processor())
    return {"date": datetime.now(UTC).strftime("%Y-%m-%d"), "commit": commit or "unknown",
            "cores": os.cpu_count(), "cpu": cpu, "python": platform.python_version(), "versions": versions,
            "load": round(os.getloadavg()[0], 1) if hasattr(os, "getloadavg") else None}


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30).stdout.strip()
    except OSError:
        return ""


def _read(path: str) -> str:
    try:
        return Path(path).read_text()
    except OSError:
        return ""


def provenance(saved: Mapping, stem: str) -> str:
    """A line naming when, where and how the figures of ``bench/<stem>.py`` were measured."""
    run = saved[stem]["run"]
    load = f", load average {run['load']} at the end" if run.get("load") is not None else ""
    versions = "".join(f", {k} {v}" for k, v in run["versions"].items())
    return (f"*Measured by `python bench/{stem}.py` on {run['date']} (commit {run['commit']}): {run['cores']} cores "
            f"({run['cpu']}), Python {run['python']}{versions}{load}.*")


def write_docs(script_file: str, figures: dict) -> list[Path]:
    """Save ``figures`` as the last run of ``script_file`` and rewrite the pages' tables
    (:func:`rewrite_pages`); returns the pages changed."""
    FIGURES.mkdir(exist_ok=True)
    path = FIGURES / f"{Path(script_file).stem}.json"
    path.write_text(json.dumps({"run": run_info(), "figures": figures}, indent=1) + "\n")
    print(f"wrote {_name(path)}")
    return rewrite_pages()


def rewrite_pages() -> list[Path]:
    """Rewrite every table block of the pages from the saved figures (a block whose figures
    are not saved is left as it is, saying so); returns the pages changed."""
    saved, changed = Saved(), []
    for page in pages():
        text = page.read_text(encoding="utf-8")
        new, end = [], 0
        for block in blocks(page):
            try:
                body = render(block, saved)
            except KeyError as e:
                print(f"{_name(page)}: the table {block.name!r} of {block.script} is left as it was: "
                      f"{e.args[0]}")
                body = block.body
            new += [text[end:block.span[0]], body]
            end = block.span[1]
        new.append(text[end:])
        if "".join(new) != text:
            page.write_text("".join(new), encoding="utf-8")
            changed.append(page)
            print(f"rewrote the tables of {_name(page)}")
    return changed


def parse_options(doc: str):
    """The command line of a benchmark whose only option is ``--write-docs`` (``doc``: its docstring)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    add_option(parser)
    return parser.parse_args()


def add_option(parser) -> None:
    """The ``--write-docs`` option of a benchmark's command line."""
    parser.add_argument("--write-docs", action="store_true",
                        help="save the figures in bench/figures/ and rewrite the pages' tables from them")


def _parallel_rows(saved) -> list[list[str]]:
    """The README's rows of parallel stepping and of the master against Ecos."""
    big = saved["bench_parallel"]["figures"]["big"]
    modes, ecos = big["modes"], saved["bench_ecos"]["figures"]["rows"][-1]
    mine, theirs = ecos["median"]["master, nothing recorded"][0], ecos["median"]["Ecos --noCsv"][0]
    return [[f"two FMUs of {big['step_ms']:.1f} ms a step, {big['steps']} steps, 2 cores",
             f"{modes['auto'][0]:.2f} s (parallel stepping, the same bits)",
             f"the serial kernel {modes['1'][0]:.2f} s ({modes['1'][0] / modes['auto'][0]:.2f}x)"],
            ["the seed 000 SSP (6 FMUs), " + f"{ecos['steps']:,}".replace(",", " ") + " steps, nothing recorded",
             f"{mine:.3f} s", f"Ecos 0.7.2 `--noCsv` {theirs:.3f} s ({mine / theirs:.2f}x its time)"]]


def readme_table(saved) -> str:
    """The README's summary of the performance page, from the saved figures of six scripts."""
    est, off = saved["bench_estimators"]["figures"], saved["bench_offline"]["figures"]
    master, camp = saved["bench_master"]["figures"]["us_per_step"]["plant + source"], saved["bench_campaign"]["figures"]
    ekf, fp = est["EKF (lists)"], est["filterpy EKF (model via CasADi numpy calls)"]
    r = off["us_per_step"]
    kf = next(v for k, v in r.items() if k.startswith("ours: KF run + RTS"))
    pk, fpy = r["pykalman filter + smooth"], r["filterpy batch_filter + rts_smoother"]
    fmpy_loop, raw, python, native = master
    wall = camp["wall_s"]
    rows = [["EKF `step` from Python (cart-pole)", f"{ekf:.2f} µs",
             f"filterpy's EKF, model through CasADi: {fp:.1f} µs ({fp / ekf:.0f}x)"],
            ["KF `run` + RTS smoother, per step", f"{kf:.3f} µs",
             f"pykalman {pk:.1f} µs ({pk / kf:.0f}x), filterpy {fpy:.1f} µs ({fpy / kf:.0f}x)"],
            ["EM iteration, 2000 steps", f"{off['em_ms']:.2f} ms",
             f"pykalman {off['em_pykalman_ms']:.0f} ms ({off['em_pykalman_ms'] / off['em_ms']:.0f}x)"],
            ["master loop, plant FMU + source, per step", f"{native:.3f} µs (native kernel; its Python loop "
             f"{python:.2f} µs)", f"hand-written fmpy loop {fmpy_loop:.2f} µs, raw ctypes loop {raw:.2f} µs"],
            [f"seed 000 campaign, 4 x {camp['runs']} realisations x {len(camp['filters'])} filters x "
             f"{camp['steps']} steps", f"{wall['fast']:.2f} s (through the FMU master: {wall['master']:.2f} s)", ""]]
    rows += _parallel_rows(saved)
    stems = ("bench_estimators", "bench_offline", "bench_master", "bench_campaign", "bench_parallel", "bench_ecos")
    runs = [saved[stem]["run"] for stem in stems]
    dates = sorted({run["date"] for run in runs})
    dates = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
    loads = sorted(run["load"] for run in runs if run.get("load") is not None)
    load = f", load averages {loads[0]}-{loads[-1]} at the ends of the runs" if loads else ""
    return (table(["", "ours", "baseline"], rows) +
            f"\n\n*Measured on {dates} by `{'`, `'.join(f'bench/{stem}.py' for stem in stems)}` on "
            f"{runs[0]['cores']} cores ({runs[0]['cpu']}){load}.*")


TABLES = {"readme": readme_table}


if __name__ == "__main__":
    rewrite_pages()
