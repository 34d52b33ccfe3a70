"""The Modelica Reference FMUs as independent oracles of the master (shared by
``tests/cosim/test_reference_fmus.py`` and ``bench/bench_reference_fmus.py``, which writes
the README's table).

Located as ``../shared/reference-fmus`` from the project root or by the environment
variable ``PENDULUM_COSIM_REFERENCE_FMUS``. Every case runs one Reference FMU (FMI 2.0 or
3.0 (:func:`cases`), or FMI 1.0 (:func:`fmi1_cases`: one FMU per interface, in ``fmi1/cs``
and ``fmi1/me``); Co-Simulation, Model Exchange or Scheduled Execution, whichever interfaces it has) over
its default experiment through the master, from Python or from the command line with a
minimal scenario file, and compares it: Co-Simulation with the result the Reference-FMUs
project publishes, Model Exchange with fmpy's CVODE at relative tolerance 1e-10 (the
reference) and with fmpy's CVODE at the master's own tolerance (the error ours may have: at
most twice fmpy's), Scheduled Execution (``Clocks``) with the tick table in a comment of
its modelDescription.xml: the importer ticks its triggered input clocks at the table's
times (a ``clock_ticks`` source), and every clock's activations and tick counters must be
the table's. FMI 1.0 Co-Simulation is compared with fmpy's own Co-Simulation run (the
project publishes no FMI 1.0 results; these FMUs are an older release's).
"""
from __future__ import annotations

import contextlib
import io
import logging
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.cli import main as cli_main

ROOT = Path(__file__).parents[2]
RTOL = 1e-6          # the master's ME tolerance in these cases (and fmpy's, compared)


def _root() -> Path:
    env = os.environ.get("PENDULUM_COSIM_REFERENCE_FMUS")
    return Path(env) if env else ROOT.parent / "shared" / "reference-fmus"


def reference_dir() -> Path | None:
    """The Reference FMUs' folder, or None if it is absent."""
    d = _root()
    return d if (d / "fmi2").is_dir() and (d / "fmi3").is_dir() else None


def fmi1_dir() -> Path | None:
    """The FMI 1.0 Reference FMUs' folder (``fmi1/`` with ``cs/`` and ``me/``), or None if
    it is absent."""
    d = _root() / "fmi1"
    return d if (d / "cs").is_dir() and (d / "me").is_dir() else None


@dataclass(frozen=True)
class Case:
    """One Reference FMU run: ``model`` (file stem), FMI ``version``, ``interface``; the
    communication ``period`` [s], ``start``, ``stop`` [s]; ``parameters`` of the component;
    ``refused``: the words the refusal must contain (the FMU is not supported)."""

    model: str
    version: int
    interface: str
    period: float
    start: float = 0.0
    stop: float = 1.0
    parameters: dict = field(default_factory=dict)
    refused: str = ""

    @property
    def label(self) -> str:
        return f"{self.model}-fmi{self.version}-{self.interface}"


def tick_table(case: Case) -> dict[str, list[float]]:
    """The expected activations of a clocked Reference FMU, from the tick table in a comment
    of its modelDescription.xml: clock -> the times marked ``+`` (``?``: computed by the
    rule the table's row states, see :func:`expected_ticks`)."""
    import re
    import zipfile

    with zipfile.ZipFile(fmu_path(case)) as z:
        text = z.read("modelDescription.xml").decode()
    comment = re.search(r"<!--(.*?)-->", text, re.S).group(1)
    lines = [ln for ln in comment.splitlines() if ln.strip()]
    head = next(ln for ln in lines if ln.startswith("time"))
    cols = [(m.start(), float(m.group())) for m in re.finditer(r"\d+(\.\d+)?", head)]
    table = {}
    for ln in lines:
        name = ln.split()[0]
        if name == "time":
            continue
        table[name] = [t for pos, t in cols if pos < len(ln) and ln[pos] in "+?"]
        table[name + ":marks"] = "".join(ln[pos] if pos < len(ln) else " " for pos, _ in cols)
    return table


def expected_ticks(case: Case) -> dict[str, list[float]]:
    """Every clock's expected activation times: the table's ``+`` marks, and the output
    clock's ``?`` row by its stated rule (active in a partition that makes the total of
    input ticks a multiple of 5), partitions at one time in priority order."""
    import zipfile

    from lxml import etree

    table = tick_table(case)
    with zipfile.ZipFile(fmu_path(case)) as z:
        root = etree.fromstring(z.read("modelDescription.xml"))
    inputs = sorted((el for el in root.find("ModelVariables") if el.tag == "Clock" and el.get("causality") == "input"),
                    key=lambda el: int(el.get("priority")))
    names = [el.get("name") for el in inputs]
    out = {n: table[n] for n in names}
    total, outs = 0, []
    for t in sorted({x for n in names for x in table[n]}):
        for n in names:                      # the partitions at one time in priority order
            if t in table[n]:
                total += 1
                if total % 5 == 0:
                    outs.append(t)
    out["outClock"] = outs
    return out


#: Period and span of each model's default experiment (Roberts: 10 steps over 1e-5..1e8 s,
#: a period that divides the span exactly; StateSpace and Feedthrough: the published grid).
EXPERIMENTS = {"BouncingBall": (0.01, 0.0, 3.0), "Dahlquist": (0.1, 0.0, 10.0), "Feedthrough": (0.1, 0.0, 2.0),
               "Resource": (0.1, 0.0, 1.0), "Stair": (0.2, 0.0, 10.0), "VanDerPol": (0.01, 0.0, 20.0),
               "StateSpace": (0.1, 0.0, 10.0), "Roberts": (9999999.999999, 1e-5, 1e8), "Clocks": (1.0, 0.0, 10.0)}
#: The refusals: (model, interface) -> the words the message must contain.
REFUSED = {("Roberts", "cs"): "fixedInternalStepSize"}


def _interfaces(path: Path) -> list[str]:
    from fmpy import read_model_description

    md = read_model_description(str(path))
    return [k for k, x in (("cs", md.coSimulation), ("me", md.modelExchange),
                           ("se", getattr(md, "scheduledExecution", None))) if x is not None]


def cases() -> list[Case]:
    """Every case: each Reference FMU of both versions, each of its interfaces."""
    d = reference_dir()
    out = []
    for version in (2, 3):
        names = sorted(p.stem for p in (d / f"fmi{version}").glob("*.fmu")) if d else []
        for model in names:
            period, start, stop = EXPERIMENTS.get(model, (0.1, 0.0, 1.0))
            for interface in _interfaces(d / f"fmi{version}" / f"{model}.fmu"):
                refused = REFUSED.get((model, interface), "")
                out.append(Case(model, version, interface, period, start, stop, refused=refused))
    return out


def fmi1_cases() -> list[Case]:
    """Every FMI 1.0 case: each Reference FMU of ``fmi1/cs`` and ``fmi1/me`` (an FMI 1.0 FMU
    has one interface), over its model's default experiment."""
    d = fmi1_dir()
    out = []
    for interface in ("cs", "me"):
        for model in sorted(p.stem for p in (d / interface).glob("*.fmu")) if d else []:
            period, start, stop = EXPERIMENTS.get(model, (0.1, 0.0, 1.0))
            out.append(Case(model, 1, interface, period, start, stop))
    return out


def _triggered_sources(case: Case) -> dict[str, list[float]]:
    """Scheduled Execution: each triggered input clock's activation times from the table
    (the importer is their source)."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu_path(case)))
    table = tick_table(case)
    return {v.name: table[v.name] for v in md.modelVariables
            if v.type == "Clock" and v.causality == "input" and v.intervalVariability == "triggered"}


def fmu_path(case: Case) -> Path:
    if case.version == 1:
        return fmi1_dir() / case.interface / f"{case.model}.fmu"
    return reference_dir() / f"fmi{case.version}" / f"{case.model}.fmu"


def run_api(case: Case) -> pd.DataFrame:
    """The case through the master from Python; columns named by the FMU's variables."""
    from cosim import Cosimulation, FMUComponent
    from cosim.core.clocking import ClockTicks

    if case.interface == "se":
        comp = FMUComponent("m", fmu_path(case), case.period, interface="se", parameters=case.parameters or None)
        sources = _triggered_sources(case)
        ticks = [ClockTicks(f"src_{name}", case.period, times=times) for name, times in sources.items()]
        sim = Cosimulation([comp, *ticks], {f"m.{name}": f"src_{name}.tick" for name in sources})
        df = sim.run(case.stop, case.start)
        df = df[[c for c in df.columns if c.startswith("m.")]].rename(columns=lambda c: c[2:])
        df.attrs["clock_ticks"] = sim.clock_ticks
        df.attrs["stopped"] = None
        return df
    comp = FMUComponent("m", fmu_path(case), case.period, interface=case.interface, rtol=RTOL,
                        parameters=case.parameters or None)
    df = Cosimulation([comp], {}).run(case.stop, case.start)
    stopped = df.attrs.get("stopped")
    df = df.rename(columns=lambda c: c[2:])
    df.attrs["stopped"] = stopped
    return df


def run_cli(case: Case, folder: Path, in_process: bool = True) -> tuple[pd.DataFrame | None,
                                                                          subprocess.CompletedProcess]:
    """The case through ``pendulum-cosim run`` with a minimal scenario file: the command
    line's ``main`` in this process (its output captured), or, with ``in_process=False``, a
    process of its own."""
    folder.mkdir(parents=True, exist_ok=True)
    text = (f'[simulation]\nstart_time = {case.start!r}\nstop_time = {case.stop!r}\n\n[[component]]\nname = "m"\n'
            f'type = "fmu"\npath = "{fmu_path(case)}"\nperiod = {case.period!r}\ninterface = "{case.interface}"\n')
    if case.interface == "se":
        sources = _triggered_sources(case)
        for name, times in sources.items():
            text += (f'\n[[component]]\nname = "src_{name}"\ntype = "clock_ticks"\nperiod = {case.period!r}\n'
                     f"times = {times!r}\n")
        text += "\n[connections]\n" + "".join(f'"m.{name}" = "src_{name}.tick"\n' for name in sources)
    else:
        text += f"rtol = {RTOL!r}\n"
    (folder / "s.toml").write_text(text)
    argv = ["run", str(folder / "s.toml"), "--out", str(folder / "out"), "--no-progress"]
    if in_process:                    # the command line's own main(), without a process start per case
        out, err = io.StringIO(), io.StringIO()
        handler = logging.StreamHandler(err)            # what main() configures when logging is unset
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        root, level = logging.getLogger(), logging.getLogger().level
        root.addHandler(handler)
        root.setLevel(logging.INFO)
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = cli_main(argv)
        finally:
            root.removeHandler(handler)
            root.setLevel(level)
        proc = subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())
    else:
        proc = subprocess.run([sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())",
                               *argv], cwd=folder, capture_output=True, text=True, timeout=600)
    csv = folder / "out" / "results.csv"
    if proc.returncode != 0 or not csv.exists():
        return None, proc
    df = pd.read_csv(csv, index_col="time")
    if case.interface == "se":
        df = df[[c for c in df.columns if c.startswith("m.")]]
        df.attrs["clock_ticks"] = pd.read_csv(folder / "out" / "clock_ticks.csv")
    return df.rename(columns=lambda c: c[2:]), proc


def _published(model: str) -> pd.DataFrame | None:
    p = reference_dir() / f"{model}_out.csv"
    return pd.read_csv(p) if p.exists() else None


def _numeric_columns(df: pd.DataFrame, pub: pd.DataFrame) -> tuple[dict[str, np.ndarray], list[str]]:
    """The published columns as numbers, arrays split into their elements (``y[1]``, ...),
    and the names of those not compared (String and Binary: not ports of the master)."""
    out, skipped = {}, []
    for c in pub.columns:
        if c == "time":
            continue
        col = pub[c]
        if pd.api.types.is_numeric_dtype(col):
            if c in df.columns:
                out[c] = col.to_numpy(float)
            else:
                skipped.append(c)
            continue
        text = col.astype(str)
        if text.str.fullmatch(r"\s*[-+0-9.eE]+(\s+[-+0-9.eE]+)+\s*").all():
            parts = np.array([[float(x) for x in v.split()] for v in text])
            names = [f"{c}[{i + 1}]" for i in range(parts.shape[1])]
            if all(n in df.columns for n in names):
                out.update({n: parts[:, i] for i, n in enumerate(names)})
            else:
                skipped.append(c)
            continue
        mapped = text.str.lower().map({"true": 1.0, "false": 0.0})
        if mapped.isna().any() or c not in df.columns:
            skipped.append(c)
        else:
            out[c] = mapped.to_numpy(float)
    return out, skipped


def _roberts(t, y):
    """Robertson's chemical kinetics as the Reference FMU states it (y3 = 1 - y1 - y2)."""
    y1, y2 = y
    y3 = 1.0 - y1 - y2
    return [-0.04 * y1 + 1e4 * y2 * y3, 0.04 * y1 - 1e4 * y2 * y3 - 3e7 * y2 * y2]


#: Models whose reference is an independent scipy solution of their equations (fmpy's
#: CVODE stops after 500 steps on Roberts' 1e-5..1e8 s: "mxstep steps taken").
ODES = {"Roberts": (_roberts, [1.0, 0.0], lambda y: {"y1": y[0], "y2": y[1], "y3": 1.0 - y[0] - y[1]})}


def _scipy(case: Case, times: np.ndarray, rtol: float, atol: float) -> pd.DataFrame:
    from scipy.integrate import solve_ivp

    f, y0, outputs = ODES[case.model]
    sol = solve_ivp(f, (case.start, case.stop), y0, method="Radau", t_eval=times, rtol=rtol, atol=atol)
    return pd.DataFrame(outputs(sol.y), index=pd.Index(sol.t, name="time"))


def _fmpy(case: Case, outputs: list[str], rtol: float | None, fmi_type: str = "ModelExchange") -> pd.DataFrame:
    """fmpy's Model Exchange result (CVODE at ``rtol``; or its Co-Simulation result with
    ``fmi_type="CoSimulation"``), arrays split into elements, one row per time (the
    post-event one where fmpy records an event twice)."""
    from fmpy import simulate_fmu

    res = simulate_fmu(str(fmu_path(case)), fmi_type=fmi_type, start_time=case.start, stop_time=case.stop,
                       output_interval=case.period, relative_tolerance=rtol, output=outputs)
    cols = {}
    for name in res.dtype.names:
        col = res[name]
        if col.ndim > 1:
            for i in range(col.shape[1]):
                cols[f"{name}[{i + 1}]"] = col[:, i].astype(float)
        else:
            cols[name] = col.astype(float)
    return pd.DataFrame(cols).drop_duplicates("time", keep="last").set_index("time")


def _aligned(df: pd.DataFrame, ref: pd.DataFrame, columns: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Our rows and the reference's at the reference's times (within 1e-9 relative)."""
    times = ref.index.to_numpy(float)
    at = df.index.get_indexer(times, method="nearest")
    ok = np.abs(df.index.to_numpy(float)[at] - times) <= 1e-9 * np.maximum(1.0, np.abs(times))
    return df[columns].to_numpy(float)[at[ok]], ref[columns].to_numpy(float)[ok]


def compare(case: Case, df: pd.DataFrame) -> dict:
    """How ``df`` (the master's result) compares with the case's reference.

    Returns ``error`` (the largest absolute difference), ``rows`` compared, ``reference``;
    for Co-Simulation ``missing`` (published rows we lack) and ``not_compared`` (published
    columns that are not ports: String, Binary); for Model Exchange ``peer_error`` (the
    error of fmpy, or of scipy where fmpy fails, at the master's tolerance), ``peer``,
    ``ratio`` (ours over the peer's) and ``scale`` (the largest reference value). A run the
    FMU stopped (Stair at 9 s) ends with the value after the stopping event, which fmpy's
    Model Exchange loop does not record: that row is compared with the published result
    instead."""
    if case.interface == "se":
        return _compare_ticks(case, df)
    if case.interface == "cs" and case.version == 1:
        ref = _fmpy(case, list(df.columns), None, "CoSimulation")
        ours, theirs = _aligned(df, ref, list(df.columns))
        return {"error": float(np.max(np.abs(ours - theirs), initial=0.0)), "rows": len(ours),
                "missing": len(ref) - len(ours), "reference": "fmpy's Co-Simulation run", "not_compared": []}
    if case.interface == "cs":
        pub = _published(case.model)
        if pub is None:
            return {"error": 0.0, "rows": 0, "missing": 0, "reference": "none published", "not_compared": []}
        cols, skipped = _numeric_columns(df, pub)
        ref = pd.DataFrame(cols, index=pd.Index(pub["time"].to_numpy(float), name="time"))
        ours, theirs = _aligned(df, ref, list(cols))
        err = float(np.max(np.abs(ours - theirs), initial=0.0))
        return {"error": err, "rows": len(ours), "missing": len(ref) - len(ours), "reference": "published result",
                "not_compared": skipped}
    outs = sorted({c.split("[")[0] for c in df.columns})
    stop = (df.attrs.get("stopped") or {}).get("time")
    if case.model in ODES:
        tight, reference = _scipy(case, df.index.to_numpy(float), 1e-10, 1e-16), "scipy Radau rtol 1e-10"
        try:
            same, peer = _fmpy(case, outs, RTOL), f"fmpy CVODE rtol {RTOL:g}"
        except RuntimeError as e:
            # CVODE's tolerances as fmpy and the master set them: atol = rtol x nominal (1)
            same, peer = _scipy(case, df.index.to_numpy(float), RTOL, RTOL), \
                f"scipy Radau rtol = atol = {RTOL:g} (fmpy fails: {str(e).split(':')[-1].strip()})"
    else:
        tight, reference = _fmpy(case, outs, 1e-10), "fmpy CVODE rtol 1e-10"
        same, peer = _fmpy(case, outs, RTOL), f"fmpy CVODE rtol {RTOL:g}"
    if stop is not None:
        tight, same = tight[tight.index < stop], same[same.index < stop]
    columns = [c for c in df.columns if c in tight.columns]
    ours, ref = _aligned(df, tight, columns)
    peers, ref2 = _aligned(same, tight, columns)
    err = float(np.max(np.abs(ours - ref), initial=0.0))
    peer_err = float(np.max(np.abs(peers - ref2), initial=0.0))
    floor = 1e-12 * max(1.0, float(np.max(np.abs(ref), initial=0.0)))
    out = {"error": err, "peer_error": peer_err, "ratio": (err + floor) / (peer_err + floor), "rows": len(ours),
           "reference": reference, "peer": peer, "columns": len(columns),
           "scale": float(np.max(np.abs(ref), initial=0.0))}
    if stop is not None:
        pub = _published(case.model)
        if pub is not None:
            cols, _ = _numeric_columns(df, pub)
            last = pd.DataFrame(cols, index=pd.Index(pub["time"].to_numpy(float), name="time")).loc[[stop]]
            a, b = _aligned(df, last, list(cols))
            out["error"] = max(err, float(np.max(np.abs(a - b), initial=0.0)))
            out["rows"] += len(a)
    return out


def _compare_ticks(case: Case, df: pd.DataFrame) -> dict:
    """Scheduled Execution: every clock's activations (the master's log) against
    :func:`expected_ticks`, and the FMU's tick counters at each of the table's times
    (``<clock>Ticks`` = the activations so far, ``totalInClockTicks`` their sum)."""
    want = expected_ticks(case)
    log = df.attrs["clock_ticks"]
    horizon = max(t for ts in tick_table(case).values() if isinstance(ts, list) for t in ts)
    got = {name: [t for t, c in zip(log["time"], log["clock"]) if c == f"m.{name}" and t <= horizon + 1e-9]
           for name in want}
    wrong = {name: (got[name], want[name]) for name in want if got[name] != want[name]}
    times = sorted({t for ts in want.values() for t in ts})
    err = 0.0
    for t in times:
        row = df.loc[t]
        total = 0
        for name in want:
            if name == "outClock":
                continue
            n = sum(1 for x in want[name] if x <= t)
            total += n
            err = max(err, abs(row[f"{name}Ticks"] - n))
        outs = sum(x <= t for x in want["outClock"])
        err = max(err, abs(row["totalInClockTicks"] - total), abs(row["outClock"] - outs))
    return {"error": float(err), "rows": len(times), "missing": 0, "not_compared": [], "wrong_ticks": wrong,
            "ticks": got, "reference": "the tick table of its model description"}
