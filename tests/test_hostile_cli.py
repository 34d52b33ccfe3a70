"""The hostile user at the command line, second round (issue 20): ``--out`` never destroys
what the project did not write; every scenario key, ``--set`` value, settings file and SSP
attribute is checked with its name in the message; parsed files have size and depth
limits; builds end cleanly on Ctrl-C and SIGTERM. Each try: one ``error:`` line (exit 2)
or an interruption (130), no traceback, the user's files byte for byte as they were, no
folder or temporary file left behind."""
from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import zipfile
from pathlib import Path

import pandas as pd
import pytest
from testkit.processes import processes_mentioning

from cosim.cli import main
from cosim.output import MARKER

CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]

GOOD = """
[simulation]
stop_time = 0.05

[[component]]
name = "c"
type = "constant"
period = 0.01
value = 1.0
"""


def snapshot(folder: Path) -> dict:
    """Every file below ``folder`` and its SHA-256 (what must stay untouched)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run_cli(capsys, *args) -> tuple[int, str]:
    status = main([str(a) for a in args])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    if status == 2:
        assert len([ln for ln in err.splitlines() if ln.startswith("error:")]) == 1, err
    return status, err


@pytest.fixture
def user_folder(tmp_path):
    """A folder of the user's own: files, a subfolder, the scenario itself."""
    d = tmp_path / "work"
    (d / "notes").mkdir(parents=True)
    (d / "thesis.tex").write_text("years of work")
    (d / "notes" / "a.txt").write_text("a")
    (d / "my.toml").write_text(GOOD)
    return d


# ------------------------------------------------------------------ --out: never lose a file
OUT_TRIES = [
    ("run-into-user-folder", ["run", "{d}/my.toml", "--out", "{d}"], "is not empty"),
    ("run-into-user-folder-overwrite", ["run", "{d}/my.toml", "--out", "{d}", "--overwrite"],
     "holds files pendulum-cosim did not write"),
    ("run-dot-overwrite", ["run", "my.toml", "--out", ".", "--overwrite"], "holds files pendulum-cosim did not write"),
    ("demo-into-user-folder", ["demo", "--out", "{d}"], "holds files pendulum-cosim did not write"),
    ("experiment-into-user-folder", ["experiment", "seed000", "--runs", "1", "--out", "{d}", "--overwrite"],
     "holds files pendulum-cosim did not write"),
    ("export-fmu-into-user-folder", ["export-fmu", "{d}/est.toml", "--component", "s", "--out", "{d}", "--overwrite"],
     "holds files pendulum-cosim did not write"),
    ("export-ssp-into-user-folder", ["export-ssp", "{d}/my.toml", "--out", "{d}", "--overwrite"],
     "holds files pendulum-cosim did not write"),
    ("run-into-subfolder-of-user-files", ["run", "{d}/my.toml", "--out", "{d}/notes", "--overwrite"],
     "holds files pendulum-cosim did not write (a.txt)"),
]


@pytest.mark.parametrize("label, args, words", OUT_TRIES, ids=[t[0] for t in OUT_TRIES])
def test_out_never_destroys_user_files(capsys, user_folder, monkeypatch, label, args, words):
    est = user_folder / "est.toml"
    est.write_text(GOOD + '\n[[component]]\nname = "s"\ntype = "sensor"\nperiod = 0.01\nsignals = ["u"]\n'
                   '[connections]\n"s.u" = "c.out"\n')
    before = snapshot(user_folder)
    monkeypatch.chdir(user_folder)
    status, err = run_cli(capsys, *[a.format(d=user_folder) for a in args])
    assert status == 2 and words in err, err
    assert snapshot(user_folder) == before
    assert not (user_folder / MARKER).exists()


def test_overwrite_replaces_only_a_previous_result(capsys, tmp_path):
    sc = tmp_path / "s.toml"
    sc.write_text(GOOD)
    out = tmp_path / "out"
    assert run_cli(capsys, "run", sc, "--out", out)[0] == 0
    assert (out / MARKER).exists() and (out / "results.csv").exists()
    assert run_cli(capsys, "run", sc, "--out", out, "--overwrite")[0] == 0      # ours: replaced
    (out / "mine.txt").write_text("added by the user")
    status, err = run_cli(capsys, "run", sc, "--out", out, "--overwrite")
    assert status == 2 and "mine.txt" in err and (out / "mine.txt").read_text() == "added by the user"
    assert (out / "results.csv").exists()                                      # nothing removed


@pytest.mark.parametrize("marker", ["garbage{", '{"tool": "other", "files": ["thesis.tex"]}',
                                    '{"tool": "pendulum-cosim", "files": "thesis.tex"}'])
def test_a_forged_or_foreign_marker_protects_nothing_less(capsys, tmp_path, marker):
    """A marker that is not ours (or not well formed) is no licence to delete."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "thesis.tex").write_text("x")
    (out / MARKER).write_text(marker)
    sc = tmp_path / "s.toml"
    sc.write_text(GOOD)
    status, err = run_cli(capsys, "run", sc, "--out", out, "--overwrite")
    assert status == 2 and "thesis.tex" in err and (out / "thesis.tex").exists()


def test_a_symlink_in_a_previous_result_is_not_followed(capsys, tmp_path):
    sc = tmp_path / "s.toml"
    sc.write_text(GOOD)
    out, precious = tmp_path / "out", tmp_path / "precious"
    precious.mkdir()
    (precious / "data.bin").write_text("keep")
    assert run_cli(capsys, "run", sc, "--out", out)[0] == 0
    (out / "link").symlink_to(precious)
    status, err = run_cli(capsys, "run", sc, "--out", out, "--overwrite")
    assert status == 2 and "link" in err
    assert (precious / "data.bin").read_text() == "keep"


@pytest.mark.parametrize("label, body, words", [
    ("bad-scenario", GOOD.replace("value = 1.0", "value = 'x'"), "value"),
    ("missing-key", GOOD.replace("stop_time = 0.05", ""), "stop_time"),
])
def test_a_refused_run_leaves_no_folder_parents_included(capsys, tmp_path, label, body, words):
    sc = tmp_path / "s.toml"
    sc.write_text(body)
    status, err = run_cli(capsys, "run", sc, "--out", tmp_path / "a" / "b" / "c")
    assert status == 2 and words in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_a_failing_run_keeps_its_folder_marked_and_replaceable(capsys, tmp_path):
    """A run that fails mid-way writes partial results; they are ours: --overwrite may
    replace them."""
    sc = tmp_path / "s.toml"
    sc.write_text(GOOD.replace("stop_time = 0.05", "stop_time = 1.0") + textwrap.dedent("""
        [[component]]
        name = "p"
        type = "fmu"
        model = "cartpole"
        period = 0.01
        start = { theta = 1e308, theta_dot = 1e308 }
        """))
    out = tmp_path / "out"
    status, _err = run_cli(capsys, "run", sc, "--out", out)
    assert status == 2
    assert (out / MARKER).exists()
    assert run_cli(capsys, "run", sc, "--out", out, "--overwrite")[0] == 2      # replaced, no refusal
    assert "did not write" not in capsys.readouterr().err


# ------------------------------------------------------------------ scenario keys
def _component(extra: str, kind: str = "constant", base: str = 'name = "c"\nperiod = 0.01\nvalue = 1.0') -> str:
    return f'[simulation]\nstop_time = 0.05\n\n[[component]]\ntype = "{kind}"\n{base}\n{extra}\n'


def _cartpole(extra: str) -> str:
    """One cart-pole plant FMU ``p`` with the TOML lines ``extra``."""
    return _component(extra, "fmu", 'name = "p"\nperiod = 0.01\nmodel = "cartpole"')


def _ekf(line: str, bad: str) -> str:
    """One EKF of the cart-pole, its TOML line ``line`` replaced by ``bad``."""
    keys = 'name = "e"\nperiod = 0.01\nfilter = "EKF"\nmodel = "cartpole"\nx0 = [0,0,0,0]\nP0 = 1.0\nQ = 1.0\nR = 1.0'
    return _component("", "estimator", keys.replace(line, bad))


SCENARIO_TRIES = [
    ("stop-time-text", GOOD.replace("stop_time = 0.05", 'stop_time = "five"'), "stop_time"),
    ("stop-time-bool", GOOD.replace("stop_time = 0.05", "stop_time = true"), "stop_time"),
    ("start-time-list", GOOD.replace("stop_time = 0.05", "stop_time = 0.05\nstart_time = [1]"), "start_time"),
    ("order-unknown", GOOD.replace("stop_time = 0.05", 'stop_time = 0.05\norder = "random"'), "order"),
    ("loops-unknown", GOOD.replace("stop_time = 0.05", 'stop_time = 0.05\nloops = "ignore"'), "loops"),
    ("simulation-not-a-table", 'simulation = 5\n[[component]]\nname = "c"\ntype = "constant"\nperiod = 0.01\n'
     'value = 1.0\n', "simulation"),
    ("component-not-a-list", '[simulation]\nstop_time = 0.05\n[component]\nname = "c"\n', "component"),
    ("no-components", "[simulation]\nstop_time = 0.05\n", "component"),
    ("component-without-type", '[simulation]\nstop_time = 0.05\n[[component]]\nname = "c"\nperiod = 0.01\n', "type"),
    ("component-without-name", '[simulation]\nstop_time = 0.05\n[[component]]\ntype = "constant"\nperiod = 0.01\n'
     'value = 1.0\n', "name"),
    ("component-name-number", _component("", base="name = 5\nperiod = 0.01\nvalue = 1.0"), "name"),
    ("component-name-with-dot", _component("", base='name = "a.b"\nperiod = 0.01\nvalue = 1.0'), "name"),
    ("duplicate-names", GOOD + '\n[[component]]\nname = "c"\ntype = "constant"\nperiod = 0.01\nvalue = 2.0\n',
     "duplicate"),
    ("model-parameters-without-model", '[simulation]\nstop_time = 0.05\n[[component]]\nname = "p"\n'
     'type = "plant_model"\nperiod = 0.01\nmodel_parameters = { mc = 1.0 }\n',
     "component 'p' (plant_model) needs the key 'model'"),
    ("component-name-non-ascii", _component("", base='name = "ëkf"\nperiod = 0.01\nvalue = 1.0'), "ASCII"),
    ("period-text", _component("", base='name = "c"\nperiod = "fast"\nvalue = 1.0'), "period"),
    ("period-inf", _component("", base='name = "c"\nperiod = inf\nvalue = 1.0'), "period"),
    ("value-list", _component("", base='name = "c"\nperiod = 0.01\nvalue = [1, 2]'), "value"),
    ("connections-not-a-table", GOOD + "\nconnections = 5\n", "connections"),
    ("connection-to-nothing", GOOD + '\n[connections]\n"c.in" = "d.out"\n', "unknown component"),
    ("connection-value-number", GOOD + '\n[connections]\n"c.in" = 5\n', "c.in"),
    ("recording-signals-number", GOOD + "\n[recording]\nsignals = 5\n", "signals"),
    ("recording-interval-negative", GOOD + "\n[recording]\noutput_interval = -1.0\n", "output_interval"),
    ("recording-unknown-key", GOOD + "\n[recording]\nsignal = ['c.*']\n", "signal"),
    ("stream-string", GOOD + '\n[recording]\nstream = "false"\n', "stream must be true or false"),
    ("plot-misspelled", GOOD + '\n[plot]\ntruth = ["c.out"]\nestimat = ["c.out"]\n', "estimat"),
    ("plot-short", GOOD + '\n[plot]\ntruth = ["c.out", "c.out"]\nestimate = ["c.out"]\n', "as many signals"),
    ("plot-unknown-signal", GOOD + '\n[plot]\ntruth = ["c.out"]\nestimate = ["z.out"]\n', "z.out"),
    ("plugins-missing", 'plugins = ["no_such_module_xyz"]\n' + GOOD, "no_such_module_xyz"),
    ("plugins-number", "plugins = 5\n" + GOOD, "plugins"),
    ("title-number", "title = 5\n" + GOOD, "title"),
    ("fmu-path-number", _component("", "fmu", 'name = "p"\nperiod = 0.01\npath = 5'), "path"),
    ("fmu-model-and-path", _component("", "fmu", 'name = "p"\nperiod = 0.01\npath = "x.fmu"\nmodel = "cartpole"'),
     "either model"),
    ("fmu-unknown-model", _component("", "fmu", 'name = "p"\nperiod = 0.01\nmodel = "rocket"'), "rocket"),
    ("fmu-fmi-version-4", _cartpole("fmi_version = 4"), "fmi_version"),
    ("fmu-parameters-not-table", _cartpole("parameters = 5"), "parameters"),
    ("fmu-start-unknown-variable", _cartpole("start = { z = 1.0 }"), "'z'"),
    ("fmu-start-text", _cartpole('start = { x = "one" }'), "x"),
    ("fmu-isolate-text", _cartpole('isolate = "yes"'), "isolate"),
    ("fmu-interface-unknown", _cartpole('interface = "hybrid"'), "interface"),
    ("fmu-solver-unknown", _cartpole('interface = "me"\nsolver = "dopri"'), "solver"),
    ("fmu-rtol-negative", _cartpole('interface = "me"\nrtol = -1.0'), "rtol"),
    ("estimator-unknown-filter", _ekf('filter = "EKF"', 'filter = "PF"'), "PF"),
    ("estimator-negative-period", _ekf("period = 0.01", "period = -0.01"), "period"),
    ("estimator-x0-short", _ekf("x0 = [0,0,0,0]", "x0 = [0,0]"), "x0"),
    ("estimator-P0-negative", _ekf("P0 = 1.0", "P0 = -1.0"), "P0"),
    ("sensor-noise-negative", _component("", "sensor", 'name = "s"\nperiod = 0.01\nsignals = ["u"]\n'
                                                       "noise_std = -1.0"), "noise_std"),
    ("sensor-signals-empty", _component("", "sensor", 'name = "s"\nperiod = 0.01\nsignals = []'), "signals"),
    ("table-missing-csv", _component("", "table", 'name = "t"\nperiod = 0.01\ndata = "missing.csv"'), "missing.csv"),
    ("me-system-members-text", _component("", "me_system", 'name = "m"\nperiod = 0.01\nmembers = "all"'), "members"),
]


@pytest.mark.parametrize("label, body, words", SCENARIO_TRIES, ids=[t[0] for t in SCENARIO_TRIES])
def test_scenario_keys_are_checked_by_name(capsys, tmp_path, label, body, words):
    sc = tmp_path / "s.toml"
    sc.write_text(body)
    status, err = run_cli(capsys, "run", sc, "--out", tmp_path / "out", "--no-progress")
    assert status == 2 and words in err, err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ parsed files: size and depth
def test_deep_and_huge_toml_are_refused_before_parsing(capsys, tmp_path):
    (tmp_path / "deep.toml").write_text("x = " + "[" * 5000 + "]" * 5000)
    status, err = run_cli(capsys, "run", tmp_path / "deep.toml", "--out", tmp_path / "o")
    assert status == 2 and "nested more than 64 deep" in err
    with open(tmp_path / "huge.toml", "w") as f:
        f.write("# " + "x" * (17 * 2**20) + "\n")
    status, err = run_cli(capsys, "run", tmp_path / "huge.toml", "--out", tmp_path / "o")
    assert status == 2 and "more than 16 MiB" in err
    (tmp_path / "bin.toml").write_bytes(os.urandom(4000))
    status, err = run_cli(capsys, "run", tmp_path / "bin.toml", "--out", tmp_path / "o")
    assert status == 2 and "bin.toml" in err
    assert not (tmp_path / "o").exists()


SET_TRIES = [
    ("set-deep", ["--set", "q0=" + "[" * 3000 + "]" * 3000], "nested more than 64 deep"),
    ("set-runs-huge", ["--set", "runs=1000000"], "GiB"),
    ("runs-huge", ["--runs", "1000000"], "GiB"),
    ("set-duration-huge", ["--set", "duration=1e7"], "GiB"),
    ("set-T-zero", ["--set", "T=0"], "T"),
    ("set-runs-fraction", ["--set", "runs=2.5"], "runs must be an integer"),
    ("set-runs-bool", ["--set", "runs=true"], "runs"),
    ("set-unknown", ["--set", "rnus=5"], "rnus"),
    ("set-no-equals", ["--set", "runs"], "name=value"),
    ("set-readings-unknown", ["--set", 'readings=["both"]'], "readings"),
    ("set-x0-short", ["--set", "x0=[1, 2]"], "x0"),
    ("set-q0-nan", ["--set", "q0=nan"], "q0"),
    ("set-scenarios-bad", ["--set", "scenarios=[[1]]"], "scenarios"),
    ("config-unknown", ["--config", "papr"], "papr"),
    ("settings-missing", ["--settings", "{t}/none.toml"], "none.toml"),
    ("settings-folder", ["--settings", "{t}"], "is a folder"),
    ("settings-binary", ["--settings", "{t}/bin.toml"], "bin.toml is not UTF-8 text"),
    ("settings-unknown-key", ["--settings", "{t}/unknown.toml"], "nosuch"),
    ("settings-not-toml", ["--settings", "{t}/bad.toml"], "not valid TOML"),
    ("path-unsupported", ["--path", "master", "--backend", "nope"], "backend"),
]


@pytest.mark.parametrize("label, extra, words", SET_TRIES, ids=[t[0] for t in SET_TRIES])
def test_settings_are_checked_before_the_folder_is_touched(capsys, tmp_path, label, extra, words):
    (tmp_path / "bin.toml").write_bytes(os.urandom(1000))
    (tmp_path / "unknown.toml").write_text("nosuch = 1\n")
    (tmp_path / "bad.toml").write_text("runs = = 1\n")
    args = ["experiment", "seed000", *[a.format(t=tmp_path) for a in extra], "--out", tmp_path / "o"]
    try:
        status, err = run_cli(capsys, *args)
    except SystemExit as e:                       # argparse refusals: exit 2 with a usage line
        status, err = e.code, capsys.readouterr().err
        assert "Traceback" not in err
    assert status == 2 and words in err, err
    assert not (tmp_path / "o").exists()


def test_models_duration_is_capped(capsys):
    with pytest.raises(SystemExit) as e:
        main(["models", "--duration", "1e5"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "at most 1000" in err


# ------------------------------------------------------------------ SSPs
def _ssd(body: str, exp: str = "") -> str:
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription '
            'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
            'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
            'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="s">'
            f'<ssd:System name="s"><ssd:Elements>{body}</ssd:Elements></ssd:System>{exp}'
            "</ssd:SystemStructureDescription>")


SSP_TRIES = [
    ("component-without-source", _ssd('<ssd:Component name="a"/>'), "without a source"),
    ("component-without-name", _ssd('<ssd:Component source="resources/a.fmu"/>'), "without a name"),
    ("source-outside", _ssd('<ssd:Component name="a" source="../../etc/passwd"/>'), "points outside the SSP"),
    ("source-missing", _ssd('<ssd:Component name="a" source="resources/none.fmu"/>'), "none.fmu"),
    ("not-an-fmu-type", _ssd('<ssd:Component name="a" source="x.ssp" type="application/x-ssp-package"/>'),
     "is not an FMU"),
    ("nested-system-bad-connection", _ssd('<ssd:System name="inner"><ssd:Connections><ssd:Connection '
                                          'startElement="x" startConnector="y" endConnector="z"/></ssd:Connections>'
                                          '</ssd:System>'), "names a connector that inner.x does not declare"),
    ("bad-xml", "<ssd:SystemStructureDescription <<", "not valid XML"),
    ("not-an-ssd", "<html/>", "not an SSP 1.0"),
    ("experiment-text", _ssd("", '<ssd:DefaultExperiment startTime="soon"/>'), "startTime must be a number"),
    ("experiment-inf", _ssd("", '<ssd:DefaultExperiment stopTime="INF"/>'), "stopTime must be finite"),
]


@pytest.mark.parametrize("label, ssd, words", SSP_TRIES, ids=[t[0] for t in SSP_TRIES])
def test_hostile_ssps_are_named_errors(tmp_path, label, ssd, words):
    from cosim import open_ssp

    ssp = tmp_path / "x.ssp"
    with zipfile.ZipFile(ssp, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
    before = set(Path(tempfile.gettempdir()).glob("pendulum_cosim_*"))
    from fmu_models.errors import PendulumCosimError

    with pytest.raises(PendulumCosimError, match=words.replace("(", r"\(").replace(".", r"\.")):
        with open_ssp(ssp):
            pass
    assert set(Path(tempfile.gettempdir()).glob("pendulum_cosim_*")) == before


def test_an_oversized_ssd_is_refused_before_parsing(tmp_path):
    from cosim import open_ssp
    from fmu_models.errors import FMUError

    d = tmp_path / "ssp"
    d.mkdir()
    with open(d / "SystemStructure.ssd", "w") as f:
        f.write("<!--" + "x" * (128 * 2**20) + "-->")
    t0 = time.perf_counter()
    with pytest.raises(FMUError, match="128 MiB, more than 16 MiB"):
        with open_ssp(d):
            pass
    assert time.perf_counter() - t0 < 5.0                # refused by its size, not parsed


# ------------------------------------------------------------------ builds interrupted
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process checks use /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_build_leaves_nothing_behind(tmp_path, sig):
    """Ctrl-C or SIGTERM while the plant FMUs compile (a cold cache): exit 130, no compiler
    process, no temporary folder, no half-written FMU, no empty --out."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp), "PENDULUM_COSIM_CACHE": str(tmp_path / "cache")}
    out = tmp_path / "a" / "fmus"
    proc = subprocess.Popen([sys.executable, "-m", "fmu_models", "build", "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    # until the compiler runs (its private temporary folder exists); not merely the first
    # file in TMPDIR, which is the probe tempfile writes and removes to test the folder, and
    # a signal inside that probe can leave it behind (Python's tempfile, not ours)
    while not list(tmp.glob("pendulum_cosim_cc_*")) and proc.poll() is None and time.monotonic() - t0 < 60:
        time.sleep(0.01)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err
    assert proc.returncode in (0, 130), err
    time.sleep(0.2)
    assert list(tmp.iterdir()) == [], list(tmp.rglob("*"))
    assert processes_mentioning(str(tmp)) == []
    if proc.returncode == 130:
        assert not out.exists() or all(p.suffix == ".fmu" for p in out.iterdir())
        assert (tmp_path / "a").exists() == out.exists()


def test_the_corpus_is_large():
    n = len(OUT_TRIES) + len(SCENARIO_TRIES) + len(SET_TRIES) + len(SSP_TRIES)
    assert n >= 80


# ------------------------------------------------------------------ an FMU or an SSP as the run
@pytest.fixture(scope="module")
def plant_fmu(tmp_path_factory):
    from fmu_models import build_fmu

    return build_fmu("cartpole", tmp_path_factory.mktemp("plant"))


FILE_RUN_TRIES = [
    ("not-a-zip", lambda d, f: (d / "m.fmu").write_bytes(b"\x00garbage") and [d / "m.fmu"],
     "m.fmu is not an FMU: not a zip archive"),
    ("empty-zip", lambda d, f: _zip(d / "m.fmu", {}) and [d / "m.fmu"], "neither a modelDescription.xml"),
    ("bad-description", lambda d, f: _zip(d / "m.fmu", {"modelDescription.xml": b"<fmi"}) and [d / "m.fmu"],
     "m.fmu"),
    ("no-binary", lambda d, f: _zip(d / "m.fmu", {"modelDescription.xml": _member(f, "modelDescription.xml")})
     and [d / "m.fmu"], "m.fmu"),
    ("unknown-start", lambda d, f: [f, "--start", "nope=1"], "has no variable 'nope'"),
    ("start-not-a-number", lambda d, f: [f, "--start", "mc=heavy"], "is not a number, true/false or a list"),
    ("start-out-of-range", lambda d, f: [f, "--start", "mc=-1", "--stop-time", "0.1"], "mc"),
    ("stop-before-start", lambda d, f: [f, "--start-time", "2", "--stop-time", "1"], "must be after start_time"),
    ("step-not-a-multiple", lambda d, f: [f, "--stop-time", "1", "--step-size", "0.3"], "whole number of base steps"),
    ("step-zero", lambda d, f: [f, "--step-size", "0"], "--step-size must be > 0"),
    ("stop-inf", lambda d, f: [f, "--stop-time", "inf"], "--stop-time must be finite"),
    ("unknown-output", lambda d, f: [f, "--outputs", "nope"], "'nope' is not an FMU output"),
    ("input-missing", lambda d, f: [f, "--input", d / "none.csv"], "cannot read the table"),
    ("input-binary", lambda d, f: (d / "u.csv").write_bytes(b"\xff\xfe\x00\x01") and [f, "--input", d / "u.csv"],
     "input"),
    ("input-no-time", lambda d, f: (d / "u.csv").write_text("F\n1\n") and [f, "--input", d / "u.csv"],
     "needs a 'time' column"),
    ("input-unknown-column", lambda d, f: (d / "u.csv").write_text("time,G\n0,1\n") and [f, "--input", d / "u.csv"],
     "input column 'G' is not an input of the FMU"),
    ("input-nan", lambda d, f: (d / "u.csv").write_text("time,F\n0,nan\n") and [f, "--input", d / "u.csv"],
     "NaN or inf"),
    ("input-backwards", lambda d, f: (d / "u.csv").write_text("time,F\n1,0\n0,1\n") and [f, "--input", d / "u.csv"],
     "non-decreasing"),
    ("interface-missing", lambda d, f: [f, "--interface", "se"], "no Scheduled Execution interface"),
    ("stream", lambda d, f: [f, "--stream"], "--stream: an FMU run records in memory"),
    ("ssp-folder-empty", lambda d, f: (d / "s").mkdir() or [d / "s"], "is a folder, not a scenario file"),
    ("ssp-input-option", lambda d, f: _zip(d / "s.ssp", {"SystemStructure.ssd": b"<x/>"}) and
     [d / "s.ssp", "--input", "u.csv"], "--input: for an FMU run, not an SSP"),
    ("ssd-garbage", lambda d, f: (d / "s.ssd").write_text("<oops") and [d / "s.ssd"], "not valid XML"),
    ("scenario-with-fmu-options", lambda d, f: ["seed000_cartpole", "--start", "x=1"], "--start: for an FMU or SSP"),
]


def _zip(path: Path, members: dict) -> bool:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return True


def _member(fmu: Path, name: str) -> bytes:
    with zipfile.ZipFile(fmu) as z:
        return z.read(name)


@pytest.mark.parametrize("label, make, words", FILE_RUN_TRIES, ids=[t[0] for t in FILE_RUN_TRIES])
def test_hostile_fmu_and_ssp_runs_are_named_errors(capsys, tmp_path, plant_fmu, label, make, words):
    """Each try: one line naming the problem, exit 2, no traceback, no --out folder left."""
    args = make(tmp_path, plant_fmu)
    before = set(Path(tempfile.gettempdir()).glob("pendulum_cosim_*"))
    try:
        status, err = run_cli(capsys, "run", *args, "--out", tmp_path / "out", "--no-progress")
    except SystemExit as e:                   # refused by the argument parser: its usage and one error line
        status, err = e.code, capsys.readouterr().err
    assert status == 2 and words in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()
    assert set(Path(tempfile.gettempdir()).glob("pendulum_cosim_*")) == before


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process checks use /proc")
def test_an_interrupted_fmu_run_keeps_its_rows_and_leaves_nothing_behind(tmp_path, plant_fmu):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    (tmp_path / "u.csv").write_text("time,F\n0,0\n1,1\n")          # a Python input: about 3 us a step
    proc = subprocess.Popen([*CLI, "run", str(plant_fmu), "--stop-time", "1e4", "--input", str(tmp_path / "u.csv"),
                             "--outputs", "x", "--out", str(out), "--no-progress"],
                            env={**os.environ, "TMPDIR": str(tmp)}, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    t0 = time.monotonic()
    while not list(tmp.glob("pendulum_cosim_fmu_*")) and proc.poll() is None and time.monotonic() - t0 < 60:
        time.sleep(0.01)
    time.sleep(0.5)                                  # into the run
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted at t = " in err
    partial = pd.read_csv(out / "results.partial.csv", index_col="time")
    assert len(partial) > 1 and list(partial.columns) == ["x"]
    assert list(tmp.iterdir()) == []
