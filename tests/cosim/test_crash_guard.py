"""An FMU whose code kills the master's process (not isolated): the crash guard names the
component, the FMI function and the time, tells the user to isolate it, keeps the rows
streamed so far as the partial Parquet file and removes the run's temporary folders; the
process still ends by its signal. A crash elsewhere passes through untouched."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pandas as pd
import pyarrow as pa
import pytest
from testkit.chaos import CRASH, scenario

from cosim.core import salvage

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the guard's checks read POSIX signals")

#: The chaos FMU with these parameters crashes (SIGSEGV) in fmi2SetReal at t = 2.1 s.
CRASHING = {"seed": 3, "rate": 0.0005, "actions": CRASH}


def _script(fmu, out, engine: str, chunk: int = 50) -> str:
    return textwrap.dedent(f"""
        from cosim import Cosimulation, FMUComponent, Sine
        comp = FMUComponent("chaos", {str(fmu)!r}, 0.01, parameters={CRASHING!r})
        sim = Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {{"chaos.u": "src.out"}}, engine={engine!r})
        sim.run_to_parquet({str(out)!r}, 500.0, chunk_rows={chunk}, progress=False)
        """)


def _leftovers(folder) -> list[str]:
    return sorted(p for p in os.listdir(folder) if p.startswith("pendulum_cosim_"))


@pytest.mark.parametrize("engine", ["python", "native"])
def test_a_crash_names_the_fmu_the_call_and_the_time_and_keeps_the_streamed_rows(chaos_fmu, tmp_path, engine):
    out = tmp_path / "out" / "r.parquet"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp), "CHAOS_LOG": str(tmp_path / "chaos.log")}
    proc = subprocess.run([sys.executable, "-c", _script(chaos_fmu, out, engine)], capture_output=True,
                          text=True, env=env, timeout=300)
    assert proc.returncode == -signal.SIGSEGV, proc.stderr
    line = next(x for x in proc.stderr.splitlines() if x.startswith("error: the FMU"))
    assert "component 'chaos'" in line and "(SIGSEGV) in fmi2SetReal at t = 2.1 s" in line, line
    assert "isolate = true" in line
    assert "Traceback" not in proc.stderr
    df = pd.read_parquet(out.with_name("r.partial.parquet"))
    assert len(df) == 200 and df.index[-1] == pytest.approx(1.99)        # every chunk of 50 before the crash
    assert list(df.columns) == ["src.out", "chaos.x", "chaos.y", "chaos.z"]
    assert sorted(os.listdir(out.parent)) == ["r.partial.parquet"]       # no unfinished file, no stream
    assert os.listdir(tmp) == []                        # the FMU's unpacked folder removed, and nothing else left


@pytest.mark.slow
def test_the_command_line_says_it_in_one_line(chaos_fmu, tmp_path):
    text = scenario(chaos_fmu, f"seed = 3, rate = 0.0005, actions = {CRASH}", 5.0, stream=True)
    (tmp_path / "s.toml").write_text(text)
    out = tmp_path / "out"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "CHAOS_LOG": str(tmp_path / "chaos.log"), "TMPDIR": str(tmp)}
    proc = subprocess.run([sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())", "run",
                           str(tmp_path / "s.toml"), "--out", str(out)], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == -signal.SIGSEGV
    errors = [x for x in proc.stderr.splitlines() if x.startswith("error:")]
    assert len(errors) == 1 and "component 'chaos'" in errors[0] and "t = 2.1 s" in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not [p for p in os.listdir(out) if p.endswith((".tmp", ".arrows"))]
    assert os.listdir(tmp) == []                                          # no temporary folder left behind


def test_a_crash_outside_any_fmu_passes_through_untouched(chaos_fmu, tmp_path):
    """The guard is installed (an FMU was loaded) but the crash is the caller's own: no word
    from the guard, the process ends by the same signal."""
    code = textwrap.dedent(f"""
        import ctypes
        from cosim import FMUComponent, Cosimulation, Sine
        comp = FMUComponent("chaos", {str(chaos_fmu)!r}, 0.01)
        Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {{"chaos.u": "src.out"}}).run(0.1, progress=False)
        from cosim.core import crash_guard
        assert crash_guard.active()
        ctypes.string_at(0)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "CHAOS_LOG": str(tmp_path / "chaos.log")})
    assert proc.returncode == -signal.SIGSEGV
    assert "error: the FMU" not in proc.stderr


@pytest.mark.slow
def test_python_s_own_crash_report_still_follows(chaos_fmu, tmp_path):
    """A handler installed before (here Python's faulthandler) still runs after the guard."""
    out = tmp_path / "r.parquet"
    code = "import faulthandler; faulthandler.enable()\n" + _script(chaos_fmu, out, "python")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "CHAOS_LOG": str(tmp_path / "chaos.log")})
    assert proc.returncode == -signal.SIGSEGV
    assert "error: the FMU of component 'chaos'" in proc.stderr and "Fatal Python error" in proc.stderr


def _stream(path, batches: int) -> pa.Schema:
    schema = pa.schema([("time", pa.float64()), ("a", pa.float64()), ("n", pa.int64())])
    with pa.OSFile(str(path), "wb") as f, pa.ipc.new_stream(f, schema) as w:
        for b in range(batches):
            w.write_table(pa.table({"time": [b + 0.0, b + 0.5], "a": [1.0, 2.0], "n": [2**62 + b, -b]}, schema=schema))
    return schema


def test_salvage_keeps_every_complete_chunk_of_a_cut_stream(tmp_path):
    ipc, tmp, partial = tmp_path / ".r.arrows", tmp_path / ".r.tmp", tmp_path / "r.partial.parquet"
    _stream(ipc, 3)
    data = ipc.read_bytes()
    ipc.write_bytes(data[:-30])                       # the third chunk cut while it was written
    tmp.write_bytes(b"PAR1")
    assert salvage.salvage_stream(str(ipc), str(tmp), str(partial)) == 4
    df = pd.read_parquet(partial)
    assert list(df["n"]) == [2**62, 0, 2**62 + 1, -1]                      # exact integers
    assert not ipc.exists() and not tmp.exists()


def test_salvage_leaves_no_temporary_file_when_the_stream_is_empty_or_the_write_fails(tmp_path):
    ipc, tmp, partial = tmp_path / ".r.arrows", tmp_path / ".r.tmp", tmp_path / "r.partial.parquet"
    _stream(ipc, 0)                                   # a schema, no chunk
    assert salvage.salvage_stream(str(ipc), str(tmp), str(partial)) == 0
    assert list(tmp_path.iterdir()) == []
    _stream(ipc, 2)
    partial.mkdir()                                   # the rename into place fails
    with pytest.raises(OSError):
        salvage.salvage_stream(str(ipc), str(tmp), str(partial))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.partial.parquet"]

def test_salvage_of_nothing_and_bad_arguments(tmp_path, capsys):
    ipc = tmp_path / ".r.arrows"
    ipc.write_bytes(b"")
    assert salvage.salvage_stream(str(ipc), str(tmp_path / "x.tmp"), str(tmp_path / "p.parquet")) == 0
    assert not (tmp_path / "p.parquet").exists() and not ipc.exists()
    folder = tmp_path / "pendulum_cosim_fmu_x"
    folder.mkdir()
    assert salvage.main(["--remove", str(folder), "--what", "--stream", "only-one"]) == 2
    assert not folder.exists()
    err = capsys.readouterr().err
    assert "unknown argument '--what'" in err and "Traceback" not in err


@pytest.mark.slow
def test_an_isolated_fmu_s_crash_is_the_parent_s_named_error_not_the_guard_s(chaos_fmu, tmp_path):
    code = textwrap.dedent(f"""
        from cosim import Cosimulation, FMUComponent, Sine
        from fmu_models.errors import PendulumCosimError
        comp = FMUComponent("chaos", {str(chaos_fmu)!r}, 0.01, isolate=True, parameters={CRASHING!r})
        try:
            Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {{"chaos.u": "src.out"}}).run(5.0, progress=False)
        except PendulumCosimError as e:
            print("named:", e)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "CHAOS_LOG": str(tmp_path / "chaos.log")})
    assert proc.returncode == 0 and "named:" in proc.stdout and "died (signal SIGSEGV)" in proc.stdout, proc
    assert "error: the FMU" not in proc.stderr and "isolate = true" not in proc.stderr


@pytest.mark.slow
def test_a_crash_in_a_later_run_on_the_kept_library_is_named_too(chaos_fmu, tmp_path):
    """Between runs a component keeps its FMU's library loaded: the guard still knows it."""
    code = textwrap.dedent(f"""
        from cosim import Cosimulation, FMUComponent, Sine
        comp = FMUComponent("chaos", {str(chaos_fmu)!r}, 0.01, parameters={CRASHING!r})
        sim = Cosimulation([Sine("src", 0.01, 1.0, 1.0), comp], {{"chaos.u": "src.out"}})
        assert len(sim.run(1.0, progress=False)) == 101
        sim.run(5.0, progress=False)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "CHAOS_LOG": str(tmp_path / "chaos.log")})
    assert proc.returncode == -signal.SIGSEGV
    said = "error: the FMU of component 'chaos' crashed the process (SIGSEGV) in fmi2SetReal at t = 2.1 s"
    assert said in proc.stderr
