"""The hostile user (issue 14): every try ends in a named error (one line, exit status 2,
no traceback), and leaves no files, temporary folders or processes behind."""
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from testkit.fmu_helpers import Instance
from testkit.processes import processes_mentioning
from testkit.scenario_files import component, write_scenario

from cosim.cli import main
from cosim.components.sources import Constant
from cosim.core.master import Cosimulation
from cosim.fmi.archive import Extraction
from cosim.fmi.fmu_component import FMUComponent
from fmu_models.errors import ConfigurationError, FMUError

ROOT = Path(__file__).parents[1]
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


def _temp_entries() -> set:
    return set(Path(tempfile.gettempdir()).glob("pendulum_cosim_*"))


def cli(capsys, *args) -> tuple[int, str]:
    """Run the CLI in-process; returns (status, stderr) and checks the one-line form."""
    status = main(list(args))
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if status == 2:
        lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
        assert len(lines) == 1, err
    return status, err


def scenario(tmp_path, body: str, name="s.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


SOURCE = """
    [simulation]
    stop_time = 0.1
    [[component]]
    name = "c"
    type = "constant"
    period = 0.01
    value = 1.0
"""


# ---------------------------------------------------------------------------- files
@pytest.fixture(scope="module")
def bad_fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    (d / "garbage.fmu").write_bytes(os.urandom(2000))
    with zipfile.ZipFile(d / "badxml.fmu", "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription fmiVersion='2.0'><oops")
    with zipfile.ZipFile(d / "noxml.fmu", "w") as z:
        z.writestr("binaries/linux64/x.so", b"\0")
    with zipfile.ZipFile(d / "escape.fmu", "w") as z:
        z.writestr("modelDescription.xml", "<x/>")
        z.writestr("../../evil.txt", "x")
    # a zip bomb: 1.1 GiB of zeros in 1.1 MB
    with zipfile.ZipFile(d / "bomb.fmu", "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        with z.open("binaries/linux64/big.so", "w", force_zip64=True) as f:
            chunk = b"\0" * (1 << 24)
            for _ in range(70):
                f.write(chunk)
    return d


@pytest.mark.parametrize("fmu, message", [
    ("garbage.fmu", "not an FMU: not a zip archive"),
    ("badxml.fmu", "modelDescription.xml is not a valid FMI model description"),
    ("noxml.fmu", "it has no modelDescription.xml"),
    ("escape.fmu", "contains the unsafe path '../../evil.txt'"),
    ("bomb.fmu", "would unpack to 1120 MiB, more than the limit of 1024 MiB"),
    ("missing.fmu", "no FMU file at"),
])
def test_bad_fmu_files_are_named_errors(tmp_path, capsys, bad_fmus, fmu, message):
    before = _temp_entries()
    sc = scenario(tmp_path, f"""
        [simulation]
        stop_time = 0.1
        [[component]]
        name = "p"
        type = "fmu"
        path = "{bad_fmus / fmu}"
        period = 0.01
    """)
    status, err = cli(capsys, "run", str(sc), "--out", str(tmp_path / "out"))
    assert status == 2 and message in err
    assert not (tmp_path / "out").exists()              # the folder it made is removed again
    assert _temp_entries() == before


def test_extraction_limits_and_cleanup(tmp_path, bad_fmus):
    before = _temp_entries()
    with pytest.raises(FMUError, match="holds 3 files, more than the limit of 2"):
        with zipfile.ZipFile(tmp_path / "many.fmu", "w") as z:
            for n in ("modelDescription.xml", "a", "b"):
                z.writestr(n, "x")
        Extraction(tmp_path / "many.fmu", max_files=2)
    with pytest.raises(FMUError, match="more than the limit of 10 MiB"):
        Extraction(bad_fmus / "bomb.fmu", max_bytes=10 << 20)
    assert _temp_entries() == before


def test_a_folder_a_file_and_garbage_as_scenario(tmp_path, capsys):
    status, err = cli(capsys, "run", str(tmp_path), "--out", str(tmp_path / "o"))
    assert status == 2 and "is a folder, not a scenario file" in err
    (tmp_path / "bin.toml").write_bytes(b"\xff\xfe\x00garbage")
    status, err = cli(capsys, "run", str(tmp_path / "bin.toml"), "--out", str(tmp_path / "o"))
    assert status == 2 and "bin.toml is not UTF-8 text" in err
    (tmp_path / "afile").write_text("x")
    sc = scenario(tmp_path, SOURCE)
    status, err = cli(capsys, "run", str(sc), "--out", str(tmp_path / "afile"))
    assert status == 2 and "is a file, not a folder" in err


@pytest.mark.parametrize("body, message", [
    (SOURCE.replace("[simulation]", "[simulaton]"), "unknown keys ['simulaton']"),
    (SOURCE.replace("stop_time = 0.1", "stop_time = inf"), "stop_time [s] must be finite"),
    (SOURCE.replace("stop_time = 0.1", "stop_time = nan"), "stop_time [s] must be finite"),
    (SOURCE.replace("value = 1.0", "value = \"one\""), "c: value"),
    (SOURCE.replace('type = "constant"', 'type = "constnat"'), "unknown type 'constnat'"),
    (SOURCE.replace("period = 0.01", "period = -0.01"), "sample period"),
    (SOURCE.replace("    value = 1.0\n", ""), "component 'c' (constant) needs the key 'value'"),
    (SOURCE.replace("value = 1.0", "value = 1.0\n    vlaue = 2"),
     "component 'c' (constant) has the unknown key 'vlaue'"),
    (SOURCE + "    [[component]]\n    name = \"d\"\n    type = \"constant\"\n    period = 0.010001\n    value = 1\n",
     "periods"),
    (SOURCE.replace("period = 0.01", "period = 0.0031415926535").replace("stop_time = 0.1", "stop_time = 1e6")
     + "    [[component]]\n    name = \"d\"\n    type = \"constant\"\n    period = 0.001\n    value = 1\n",
     "periods"),
])
def test_bad_scenarios_are_refused_before_anything_runs(tmp_path, capsys, body, message):
    sc = scenario(tmp_path, body)
    status, err = cli(capsys, "run", str(sc), "--out", str(tmp_path / "out"))
    assert status == 2 and message in err, err
    assert not (tmp_path / "out").exists()


def test_a_huge_run_is_refused_with_its_size(tmp_path, capsys):
    sc = scenario(tmp_path, SOURCE.replace("stop_time = 0.1", "stop_time = 1e9"))
    status, err = cli(capsys, "run", str(sc), "--out", str(tmp_path / "out"))
    assert status == 2 and ("GiB" in err or "steps" in err), err


@pytest.mark.parametrize("args, message", [
    (["experiment", "seed000", "--runs", "-5"], "must be >= 1"),
    (["experiment", "seed000", "--runs", "0"], "must be >= 1"),
    (["experiment", "seed000", "--seed", "-1"], "must be >= 0"),
    (["experiment", "seed000", "--jobs", "-3"], "must be >= 1"),
    (["experiment", "seed000", "--runs", "many"], "must be an integer"),
    (["models", "--duration", "nan"], "must be finite"),
    (["models", "--duration", "-1"], "must be > 0"),
])
def test_bad_numbers_on_the_command_line(capsys, args, message):
    with pytest.raises(SystemExit) as e:
        main(args)
    err = capsys.readouterr().err
    assert e.value.code == 2 and message in err and "Traceback" not in err


def test_bad_settings_are_refused_before_the_output_folder_is_touched(tmp_path, capsys):
    status, err = cli(capsys, "experiment", "seed000", "--set", "q0=-1", "--out", str(tmp_path / "o"))
    assert status == 2 and "q0" in err
    status, err = cli(capsys, "experiment", "seed000", "--set", "nonsense=1", "--out", str(tmp_path / "o"))
    assert status == 2 and "nonsense" in err
    (tmp_path / "f").write_text("x")
    status, err = cli(capsys, "experiment", "seed000", "--runs", "1", "--out", str(tmp_path / "f"))
    assert status == 2 and "is a file" in err
    assert not (tmp_path / "o").exists()


def test_a_full_disk_is_an_error_and_leaves_no_half_written_results(tmp_path):
    """RLIMIT_FSIZE stands in for a full disk: writes beyond 64 kB fail with EFBIG."""
    code = ("import resource, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
            "resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536)); "
            "from cosim.cli import main; sys.exit(main())")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-c", code, "demo", "--out", str(out)], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PENDULUM_COSIM_CACHE": str(tmp_path / "cache")})
    assert proc.returncode == 2, proc.stderr
    assert "error:" in proc.stderr and "Traceback" not in proc.stderr
    # where the limit strikes first depends on file sizes: the compiler, the cache or the results
    assert any(m in proc.stderr for m in ("File too large", "File size limit exceeded", "No space",
                                           "cannot be written")), proc.stderr
    names = [p.name for p in out.rglob("*")] if out.exists() else []
    assert "results.csv" not in names and not any(n.endswith(".tmp") for n in names), names


# ---------------------------------------------------------------------------- concurrency and signals
def _wait_for(proc, path: Path, timeout=120.0):
    t0 = time.monotonic()
    while not path.exists():
        if proc.poll() is not None or time.monotonic() - t0 > timeout:
            raise AssertionError(f"{path} never appeared; stderr: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.05)


class _Stderr:
    """The stderr of a process read as it comes (a thread), to wait for a sign of progress."""

    def __init__(self, proc):
        import threading

        self.text, self.proc = "", proc
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self):
        while chunk := self.proc.stderr.read(1):
            self.text += chunk

    def wait_for(self, pattern: str, timeout: float = 180.0) -> None:
        """Until ``pattern`` (a regex) is in the stderr so far."""
        import re

        t0 = time.monotonic()
        while not re.search(pattern, self.text):
            if self.proc.poll() is not None or time.monotonic() - t0 > timeout:
                raise AssertionError(f"no {pattern!r} in the stderr: {self.text[-2000:]}")
            time.sleep(0.05)

    def rest(self) -> str:
        """The whole stderr, once the process has ended; closes its pipes."""
        self._thread.join(timeout=60)
        self.proc.stdout.close()
        self.proc.stderr.close()
        return self.text


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc")
@pytest.mark.parametrize("sig, backend", [(signal.SIGINT, "processes"),
                                          pytest.param(signal.SIGTERM, "processes", marks=pytest.mark.slow),
                                          pytest.param(signal.SIGINT, "dask", marks=pytest.mark.slow)])
def test_interrupting_a_campaign_saves_partial_results_and_ends_every_worker(tmp_path, sig, backend):
    out = tmp_path / f"campaign-{sig.name}-{backend}"
    proc = subprocess.Popen([*CLI, "experiment", "seed000", "--path", "master", "--runs", "200", "--jobs", "2",
                             "--backend", backend, "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    err = _Stderr(proc)
    err.wait_for(r"\b[1-9][0-9]*/[0-9]+ ")         # the progress bar: at least one task has finished
    proc.send_signal(sig)
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        err.rest()                  # its pipes closed: no ResourceWarning in whichever test comes next
        raise
    err = err.rest()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "WARNING" not in err and "interrupted" in err, err
    summary = out / "summary.md"
    assert summary.exists() and "PARTIAL" in summary.read_text().upper()
    time.sleep(0.5)
    # no worker left behind: none with the command's arguments, none started by spawn (its own command line)
    assert processes_mentioning(str(out)) == [] and processes_mentioning("spawn_main") == []


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc")
def test_interrupting_a_run_writes_partial_results_not_finished_ones(tmp_path):
    sc = write_scenario(tmp_path / "s.toml", 1e5, [component("fmu", "plant", 0.001, model="cartpole"),
                                                   component("constant", "f", 0.001, value=0.0)],
                        {"plant.F": "f.out"},
                        recording={"output_interval": 0.1})    # the native kernel records ~1e7 base steps a second
    out = tmp_path / "out"
    proc = subprocess.Popen([*CLI, "run", str(sc), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    err = _Stderr(proc)
    err.wait_for(r"co-simulation: +[0-9]+%")         # the progress bar: rows are being recorded
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    err = err.rest()
    assert proc.returncode == 130 and "Traceback" not in err
    names = sorted(p.name for p in out.iterdir())
    assert "results.csv" not in names and "results.partial.csv" in names, names


@pytest.mark.slow
def test_two_runs_into_one_output_folder(tmp_path):
    out = tmp_path / "out"
    procs = [subprocess.Popen([*CLI, "run", "seed000_cartpole", "--out", str(out), "--no-progress"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=300), p.communicate()[1]) for p in procs]
    codes = sorted(c for c, _ in results)
    assert codes == [0, 2], results
    err = next(e for c, e in results if c == 2)
    assert "another pendulum-cosim run is writing" in err or "is not empty" in err
    import pandas as pd

    assert len(pd.read_csv(out / "results.csv")) == 501          # the winner's files are whole
    for fmu in out.rglob("*.fmu"):
        with zipfile.ZipFile(fmu) as z:
            assert z.testzip() is None


# ---------------------------------------------------------------------------- resources
def test_temporary_folders_do_not_accumulate(fmu_paths):
    plant = FMUComponent("plant", fmu_paths["cartpole"], 0.01)
    cosim = Cosimulation([plant, Constant("f", 0.01, 0.1)], {"plant.F": "f.out"})
    cosim.run(0.05)
    before = _temp_entries()
    for _ in range(100):
        cosim.run(0.05)
    assert _temp_entries() == before


def test_a_huge_communication_step_is_an_error_not_a_hang(fmu_builds):
    for version in (2, 3):
        inst = Instance(fmu_builds["cartpole", version]).init()
        with pytest.raises(Exception):
            inst.do_step(0.0, 1e12)
        assert any("more than the limit of" in m for _, m in inst.messages), inst.messages
        inst.fmu.reset()                   # after an Error: usable again once reset
        inst.init().do_step(0.0, 0.01)
        inst.free()


@pytest.mark.parametrize("version", [2, 3])
def test_a_state_restored_right_after_instantiation_steps_on(fmu_builds, version):
    """As fmusim's --initial-fmu-state-file: a fresh instance takes a saved state and steps."""
    path = fmu_builds["cartpole", version]
    a = Instance(path).init()
    for k in range(10):
        a.set("F", 0.5)
        a.do_step(k * 0.01, 0.01)
    blob = a.serialize(a.get_state())
    a.do_step(0.1, 0.01)
    expected = a.get("x", "theta")
    b = Instance(path)                                  # instantiated only
    b.set_state(b.deserialize(blob))
    b.set("F", 0.5)
    b.do_step(0.1, 0.01)
    assert b.get("x", "theta") == expected
    a.free()
    b.free()


def test_two_fmi_versions_of_one_model_in_one_scenario(tmp_path, capsys):
    sc = write_scenario(tmp_path / "s.toml", 0.1, [component("fmu", f"p{v}", 0.01, model="cartpole", fmi_version=v)
                                                   for v in (2, 3)])
    status, _ = cli(capsys, "run", str(sc), "--out", str(tmp_path / "out"))
    assert status == 0
    import pandas as pd

    df = pd.read_csv(tmp_path / "out" / "results.csv", index_col="time")
    np.testing.assert_array_equal(df["p2.theta"], df["p3.theta"])


# ---------------------------------------------------------------------------- the compiled-code cache
CACHE_PROBE = ("import warnings, sys; warnings.simplefilter('always'); "
               "from estimators import EKF, discretize; from fmu_models import get_model; "
               "f = EKF(discretize(get_model('cartpole'), 0.01), [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1); "
               "x = f.step([0.1], [0.5, 1.8]); print(f.backend, repr(float(x[2])))")


def _probe(env: dict) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", CACHE_PROBE], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, **env}, cwd=ROOT)


@pytest.mark.slow
def test_eight_processes_fill_an_empty_cache_at_once(tmp_path):
    procs = [_probe({"PENDULUM_COSIM_CACHE": str(tmp_path / "cache")}) for _ in range(8)]
    outs = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    assert all(code == 0 for code, _, _ in outs), [e for _, _, e in outs]
    assert len({o for _, o, _ in outs}) == 1 and outs[0][1].startswith("compiled")
    leftovers = [p.name for p in (tmp_path / "cache").rglob("*") if p.is_dir() or p.suffix == ".tmp"]
    assert leftovers == [], leftovers


@pytest.mark.parametrize("damage", [pytest.param("truncate", marks=pytest.mark.slow),
                                    pytest.param("empty", marks=pytest.mark.slow), "garbage"])
def test_a_damaged_cache_entry_is_rebuilt_in_one_run(tmp_path, damage):
    env = {"PENDULUM_COSIM_CACHE": str(tmp_path)}
    first = _probe(env)
    ok_out, _ = first.communicate(timeout=300)
    libs = [p for p in tmp_path.iterdir() if p.suffix in (".so", ".dylib", ".dll")]
    assert libs
    for lib in libs:
        data = lib.read_bytes()
        lib.write_bytes({"truncate": data[: len(data) // 3], "empty": b"", "garbage": os.urandom(len(data))}[damage])
    second = _probe(env)
    out, err = second.communicate(timeout=300)
    assert second.returncode == 0 and out == ok_out, err
    assert "damaged entry" in err
    third = _probe(env)
    out, err = third.communicate(timeout=300)
    assert out == ok_out and "damaged" not in err            # repaired for good


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_cache_falls_back_to_the_vm(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        p = _probe({"PENDULUM_COSIM_CACHE": str(ro)})
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0 and out.startswith("vm") and "cannot be written" in err
    finally:
        ro.chmod(0o700)


@pytest.mark.slow
def test_an_impossible_cache_falls_back_to_the_vm_and_xdg_is_honoured(tmp_path):
    p = _probe({"PENDULUM_COSIM_CACHE": "/proc/no/such/cache"})
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0 and out.startswith("vm") and "cannot be written" in err and "Traceback" not in err
    env = {k: v for k, v in os.environ.items() if k != "PENDULUM_COSIM_CACHE"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    proc = subprocess.run([sys.executable, "-c", CACHE_PROBE], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=300)
    assert proc.returncode == 0 and proc.stdout.startswith("compiled")
    assert any((tmp_path / "xdg" / "pendulum-cosim").iterdir())


# ---------------------------------------------------------------------------- filter inputs
def test_filter_inputs_a_careless_user_gives(tmp_path):
    from estimators import EKF, discretize
    from fmu_models import get_model
    from fmu_models.errors import InputError, TypeMismatchError

    f = EKF(discretize(get_model("cartpole"), 0.01), [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1)
    x0 = f.x.copy()
    with pytest.raises(TypeMismatchError, match="y must be numbers"):
        f.step([0.1], ["a", "b"])
    with pytest.raises(TypeMismatchError, match="u is None"):
        f.step(None, [0.5, 1.8])
    with pytest.raises(InputError, match="u contains NaN or inf"):
        f.step([np.inf], [0.5, 1.8])
    with pytest.raises(InputError, match=r"y must have shape \(2,\), got shape \(3,\)"):
        f.step([0.1], [0.5, 1.8, 0.0])
    np.testing.assert_array_equal(f.x, x0)                           # nothing changed
    assert np.isfinite(f.step([0.1], [1.5e308, 1.8])).all()         # huge but finite: accepted
    Q, R = f.Q.copy(), f.R.copy()
    with pytest.raises(ConfigurationError, match="R is not positive definite"):
        f.set_noise(Q=0.5, R=-1)
    np.testing.assert_array_equal(f.Q, Q)                           # atomic: Q unchanged too
    np.testing.assert_array_equal(f.R, R)
