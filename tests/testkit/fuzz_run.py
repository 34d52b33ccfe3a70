"""The call-sequence fuzzer of the project's FMUs (tests/data/fuzz/fuzz.c): build an FMU's own
``sources/`` and the driver with AddressSanitizer and UndefinedBehaviorSanitizer, run seeded
sequences, read the answer back.

Used by tests/fmu_models/test_fmu_state_machine.py (short runs, the regression cases) and
bench/bench_soak.py (the long campaign). From the repository root a failing sequence replays
with the command :func:`replay_command` prints::

    PYTHONPATH=.:tests python -m testkit.fuzz_run FMU --seed S --first I --count 1 --trace
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import fmpy
from fmpy import read_model_description

FUZZ_DIR = Path(__file__).parents[1] / "data" / "fuzz"
DRIVER = FUZZ_DIR / "fuzz.c"
HEADERS = Path(fmpy.__file__).parent / "c-code"
#: Sanitizers of every fuzz build: memory errors, leaks, undefined behaviour (out-of-range
#: float-to-integer conversions included), each ending the process at its first report.
SAN_FLAGS = ("-fsanitize=address,undefined,float-cast-overflow", "-fno-sanitize-recover=all",
             "-fno-omit-frame-pointer", "-g", "-O1")
SAN_ENV = {"ASAN_OPTIONS": "detect_leaks=1:halt_on_error=1:abort_on_error=0",
           "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
SANITIZER_MARKS = ("ERROR: AddressSanitizer", "ERROR: LeakSanitizer", "runtime error:",
                   "UndefinedBehaviorSanitizer")
_TYPES = {"Real": "R", "Float64": "R", "Integer": "I", "Int32": "I", "Enumeration": "L", "Int64": "L",
          "Boolean": "B", "Clock": "K"}
_CAUSALITY = {"parameter": "p", "calculatedParameter": "c", "input": "i", "output": "o", "local": "l",
              "independent": "t", "structuralParameter": "p"}
_VARIABILITY = {"constant": "c", "fixed": "f", "tunable": "t", "discrete": "d", "continuous": "n"}
_INITIAL = {"exact": "e", "approx": "a", "calculated": "c"}


@dataclass
class Target:
    """An FMU built for fuzzing: its sanitized library, the driver, the variable table."""

    fmu: Path
    version: int
    lib: Path
    driver: Path
    vars_file: Path
    token: str
    cs: bool
    me: bool
    directional: bool
    clock: tuple | None = None      # a clocked FMU: (its input clock's value reference, interval [s])


@dataclass
class Result:
    """One run of the driver: ``outcome`` ``"ok"``, ``"violation"``, ``"hang"``,
    ``"sanitizer"`` or ``"crash"``; the summary counts; the report (stderr's end)."""

    outcome: str
    counts: dict = field(default_factory=dict)
    report: str = ""
    returncode: int = 0
    command: list = field(default_factory=list)


def _compile(cmd: list[str], out: Path, what: str) -> None:
    """Run the compiler command ``cmd`` writing ``out`` (atomically: another process never
    sees a half-written file)."""
    part = out.with_name(f"{out.name}.{os.getpid()}.part")
    r = subprocess.run([*cmd, "-o", str(part)], capture_output=True, text=True, timeout=900)
    if r.returncode != 0:
        part.unlink(missing_ok=True)
        raise RuntimeError(f"building {what} failed:\n{' '.join(cmd)}\n{r.stdout}{r.stderr}")
    os.replace(part, out)


def _write_if_changed(path: Path, data: bytes) -> None:
    if not path.exists() or path.read_bytes() != data:
        part = path.with_name(f"{path.name}.{os.getpid()}.part")
        part.write_bytes(data)
        os.replace(part, path)


def _source_files(md, sources: Path) -> list[str]:
    for b in md.buildConfigurations:
        files = [f for s in b.sourceFileSets for f in s.sourceFiles]
        if files:
            return files
    return sorted(p.name for p in sources.glob("*.c"))


def variable_table(md) -> str:
    """The driver's variable file (see fuzz.c): one variable a line."""
    states = {v.derivative.valueReference for v in md.modelVariables if v.derivative is not None}
    lines = []
    for v in md.modelVariables:
        flag = "S" if v.valueReference in states else "D" if v.derivative is not None else "K" if v.clocks else "-"
        start = "-" if v.start in (None, "") else str(int(v.start == "true") if v.type == "Boolean"
                                                      and isinstance(v.start, str) else v.start)
        lines.append(f"{v.valueReference} {_TYPES.get(v.type, 'R')} {_CAUSALITY.get(v.causality, 'l')} "
                     f"{_VARIABILITY.get(v.variability, 'n')} {_INITIAL.get(v.initial, '-')} {start} {flag}")
    return "\n".join(lines) + "\n"


def build_driver(folder: Path) -> Path:
    """The sanitized driver in ``folder`` (built once)."""
    exe = Path(folder) / "fuzz"
    if not exe.exists():
        Path(folder).mkdir(parents=True, exist_ok=True)
        _compile(["gcc", *SAN_FLAGS, "-std=c99", f"-I{HEADERS}", f"-I{FUZZ_DIR}", str(DRIVER), "-ldl", "-lm"],
                 exe, "the fuzz driver")
    return exe


def build_target(fmu: str | Path, folder: str | Path, mutate: dict | None = None) -> Target:
    """Extract ``fmu``, build its ``sources/`` (the files its build description names) into a
    sanitized shared library in ``folder``, and the driver beside it. ``mutate``: {source file:
    (text, replacement) or a list of them} changes made first (to check that the fuzzer finds
    a broken FMU)."""
    fmu, folder = Path(fmu), Path(folder)
    md = read_model_description(str(fmu))
    version = 3 if md.fmiVersion.startswith("3") else 2
    work = folder / f"{fmu.stem}-fmi{version}{'-mutant' if mutate else ''}"
    sources = work / "sources"
    work.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/") and not name.endswith("/"):
                sources.mkdir(exist_ok=True)
                _write_if_changed(sources / Path(name).name, z.read(name))
    for name, changes in (mutate or {}).items():
        src = (sources / name).read_text()
        for text, replacement in [changes] if isinstance(changes[0], str) else changes:
            if text not in src:
                raise ValueError(f"{name} has no {text!r} to change")
            src = src.replace(text, replacement)
        _write_if_changed(sources / name, src.encode())
    lib = work / "fmu_asan.so"
    if not lib.exists():
        files = [str(sources / f) for f in _source_files(md, sources)]
        _compile(["gcc", "-shared", "-fPIC", *SAN_FLAGS, "-std=c99", "-D_POSIX_C_SOURCE=200809L", f"-I{sources}",
                  f"-I{HEADERS}", *files, "-lm"], lib, f"{fmu.name} with sanitizers")
    vars_file = work / "variables.txt"
    _write_if_changed(vars_file, variable_table(md).encode())
    cs = md.coSimulation is not None
    with zipfile.ZipFile(fmu) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
    iface = root.find("CoSimulation" if cs else "ModelExchange")
    # fmpy reads FMI 3.0's providesDirectionalDerivatives under its FMI 2.0 name, and no intervalDecimal
    directional = iface.get("providesDirectionalDerivatives" if version == 3 else "providesDirectionalDerivative")
    clock = None
    if version == 3 and any(v.type == "Clock" for v in md.modelVariables):
        k = root.find("ModelVariables/Clock")
        clock = (int(k.get("valueReference")), float(k.get("intervalDecimal")))
    return Target(fmu, version, lib, build_driver(folder), vars_file,
                  md.guid if version == 2 else md.instantiationToken, cs, md.modelExchange is not None,
                  directional == "true", clock)


def command(t: Target, seed: int, first: int, count: int, calls: int = 60, timeout: float = 10.0,
            trace: bool = False) -> list[str]:
    """The driver's command line for sequences ``first`` .. ``first + count - 1`` of ``seed``."""
    return [str(t.driver), f"lib={t.lib}", f"fmi={t.version}", f"cs={int(t.cs)}", f"me={int(t.me)}",
            f"dd={int(t.directional)}", f"token={t.token}", f"vars={t.vars_file}", f"seed={seed}",
            f"first={first}", f"count={count}", f"calls={calls}", f"timeout={timeout}", f"trace={int(trace)}",
            *([f"clock={t.clock[0]}", f"interval={t.clock[1]!r}"] if t.clock else [])]


def replay_command(t: Target, seed: int, seq: int) -> str:
    """The shell command (from the repository root) that replays sequence ``seq`` of ``seed``."""
    return (f"PYTHONPATH=.:tests python -m testkit.fuzz_run {t.fmu} --seed {seed} --first {seq} --count 1 "
            "--trace")


def run(t: Target, seed: int, first: int = 0, count: int = 100, calls: int = 60, timeout: float = 10.0,
        trace: bool = False, wall: float = 3600.0) -> Result:
    """Run the driver; the outcome, counts and report (see :class:`Result`)."""
    cmd = command(t, seed, first, count, calls, timeout, trace)
    env = {**os.environ, **SAN_ENV}
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=wall, env=env)
    except subprocess.TimeoutExpired as e:
        return Result("hang", {}, f"the driver ran longer than {wall} s: {e}", -1, cmd)
    counts = {}
    for line in r.stdout.splitlines():
        if line.startswith("FUZZ "):
            counts = {k: (int(v) if v.isdigit() else v) for k, v in re.findall(r"(\w+)=(\S+)", line)}
    err = r.stderr
    if any(m in err for m in SANITIZER_MARKS):
        outcome = "sanitizer"
    elif "HANG " in err:
        outcome = "hang"
    elif "VIOLATION " in err:
        outcome = "violation"
    elif r.returncode != 0:
        outcome = "crash"
    else:
        outcome = "ok"
    heads = [ln for ln in err.splitlines() if ln.startswith(("VIOLATION ", "HANG ", "DIED "))
             or any(m in ln for m in SANITIZER_MARKS)][:6]
    report = err if trace or len(err) <= 12000 else "\n".join(heads) + "\n[...]\n" + err[-12000:]
    m = re.search(r"^(?:VIOLATION|HANG|DIED) seed=\d+ seq=(\d+)", err, re.M)
    if outcome != "ok" and m:
        report += f"\nreplay: {replay_command(t, seed, int(m.group(1)))}"
    return Result(outcome, counts, report, r.returncode, cmd)


#: The FMUs the fuzzer covers: {kind: [labels]}. The clocked kind (the clocked form of an
#: estimator and a signal FMU) exists in FMI 3.0 only (:data:`FMI3_ONLY`).
FMU_KINDS = {"plant": ["cartpole", "iwp"], "estimator": ["ekf", "mfiae"], "signal": ["prbs", "sensor"],
             "clocked": ["ekf_clocked", "sensor_clocked"]}
#: The kinds without an FMI 2.0 form.
FMI3_ONLY = ("clocked",)


def build_fmu_for(label: str, version: int, folder: str | Path) -> Path:
    """Build one of the project's FMUs (a label of :data:`FMU_KINDS`) in FMI ``version``."""
    folder = Path(folder) / f"fmi{version}"
    clocked = label.endswith("_clocked")
    label = label.removesuffix("_clocked")
    if label in ("cartpole", "iwp"):
        from fmu_models import build_fmu

        return build_fmu(label, folder, fmi_version=version)
    if label in ("ekf", "mfiae"):
        from estimators import EKF, MFIAE, discretize
        from estimators.filter_fmu import export_filter_fmu
        from fmu_models import get_model

        cp = discretize(get_model("cartpole"), 0.01)
        x0 = [0.5, 0.0, 1.8, 0.5]
        filt = EKF(cp, x0, 1.0, 0.2, 0.1) if label == "ekf" else MFIAE(cp, x0, 1.0, 1e-3, 10.0)
        return export_filter_fmu(filt, folder, version, name=f"Fuzz{label.upper()}{'Clocked' * clocked}",
                                 clocked=clocked)
    from fmu_models.export.signal_fmu import SignalSpec, build_signal_fmu, channel_params

    if label == "prbs":
        spec = SignalSpec("prbs", 0.01, ["out"],
                          reals=[("amplitude", 1.0, "real", "amplitude"), ("bit_time", 0.05, "positive", "bit [s]"),
                                 ("offset", 0.0, "real", "offset")],
                          ints=[("order", 7, 2, 16, "LFSR length"), ("seed", 5, 0, 2**31 - 1, "start state")])
    else:
        sig = ["a", "b"]
        spec = SignalSpec("sensor", 0.01, ["y_a", "y_b"], inputs=sig,
                          reals=channel_params("std", sig, [0.1, 0.2], "nonnegative", "noise std")
                          + channel_params("bias", sig, [0.0, 0.1], "real", "bias")
                          + channel_params("quantization", sig, [0.0, 0.01], "nonnegative", "quantisation"),
                          ints=[("seed", 3, 0, 2**31 - 1, "seed")])
    return build_signal_fmu(spec, folder, version, f"Fuzz{label.capitalize()}{'Clocked' * clocked}", clocked=clocked)


#: The regression cases of cases.c (the exact call sequences of the classes found).
CASES = ("nonfinite_time", "vr_overflow", "logging_off", "event_mode_used", "after_error", "forbidden_states",
         "fmu_states", "atomic_set")


def run_case(t: Target, name: str, timeout: float = 10.0) -> Result:
    """Run regression case ``name`` of cases.c on ``t`` (outcome ``"ok"`` or why not)."""
    cmd = [*command(t, 0, 0, 1, timeout=timeout)[:8], f"timeout={timeout}", f"case={name}"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, **SAN_ENV})
    err = r.stderr
    outcome = ("sanitizer" if any(m in err for m in SANITIZER_MARKS) else "hang" if "HANG " in err
               else "ok" if r.returncode == 0 and f"CASE {name} ok" in r.stdout else "violation")
    return Result(outcome, {}, err[-8000:], r.returncode, cmd)


def main(argv: list[str] | None = None) -> int:
    """Command line: build an FMU for fuzzing and run (or replay) sequences of a seed."""
    p = argparse.ArgumentParser(description="Fuzz one FMU of the project (replay a failing sequence).")
    p.add_argument("fmu")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--calls", type=int, default=60)
    p.add_argument("--trace", action="store_true")
    p.add_argument("--build-dir", default=None)
    a = p.parse_args(argv)
    import tempfile

    folder = a.build_dir or tempfile.mkdtemp(prefix="pendulum_fuzz_")
    t = build_target(a.fmu, folder)
    res = run(t, a.seed, a.first, a.count, a.calls, trace=a.trace)
    print(res.report, file=sys.stderr)
    print(res.outcome, res.counts)
    return 0 if res.outcome == "ok" else 1


if __name__ == "__main__":
    sys.exit(main())
