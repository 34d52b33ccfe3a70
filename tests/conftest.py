"""Shared fixtures, and the test session's own environment.

The test folders mirror the packages (``tests/fmu_models``, ``tests/estimators``,
``tests/cosim``); helpers live in ``tests/testkit``. The project's packages are imported
before this folder is put on ``sys.path``, so a test folder named like a package can never
shadow them.

Hermetic: a session (all its xdist workers) has its own folder for every cache the code
under test writes: the compiled-code cache (``PENDULUM_COSIM_CACHE``), ``XDG_CACHE_HOME``,
``XDG_CONFIG_HOME``, matplotlib's (``MPLCONFIGDIR``), zig's (``ZIG_GLOBAL_CACHE_DIR``)
and wine's prefix; nothing is read from or written to the user's home, so a run does not
depend on what ran before. ``PENDULUM_COSIM_TEST_HOME=DIR`` keeps that folder in ``DIR``
across sessions instead (a developer's warm caches; CI never sets it). Each test process
is the subreaper of what it starts (:mod:`testkit.processes`), so the leftover checks look
only at its own process tree.
"""
import inspect
import os
import re
import shutil
import signal
import sys
import tempfile
from pathlib import Path

import pytest

import cosim  # noqa: F401 - the real packages first
import estimators  # noqa: F401
import fmu_models  # noqa: F401

sys.path.append(str(Path(__file__).parent))

from testkit import handwritten
from testkit.processes import become_subreaper

DATA = Path(__file__).parent / "data"
#: The environment variables pointed into the session's folder, and their subfolders.
HERMETIC = {"PENDULUM_COSIM_CACHE": "pendulum-cosim", "XDG_CACHE_HOME": "xdg-cache",
            "XDG_CONFIG_HOME": "xdg-config", "MPLCONFIGDIR": "matplotlib", "ZIG_GLOBAL_CACHE_DIR": "zig",
            "WINEPREFIX": "wine"}


def pytest_configure(config):
    """The controller (or a run without xdist) makes the session's folder and points the
    caches into it; xdist workers inherit the environment."""
    if hasattr(config, "workerinput"):
        return
    keep = os.environ.get("PENDULUM_COSIM_TEST_HOME")
    home = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="pendulum-cosim-tests-"))
    config._pendulum_session_home = None if keep else home
    for var, sub in HERMETIC.items():
        (home / sub).mkdir(parents=True, exist_ok=True)
        os.environ[var] = str(home / sub)


def pytest_unconfigure(config):
    home = getattr(config, "_pendulum_session_home", None)
    if home is not None:
        shutil.rmtree(home, ignore_errors=True)


become_subreaper()


@pytest.fixture(autouse=True)
def _private_temp_folder(tmp_path_factory, monkeypatch):
    """Every test has its own temporary folder (``tempfile.gettempdir()`` and ``TMPDIR`` for
    what it starts): its checks that nothing is left behind see only its own files, however
    many tests run at once."""
    folder = tmp_path_factory.mktemp("tmp")
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    monkeypatch.setenv("TMPDIR", str(folder))

#: A test runs a command line or another program in a process of its own if its code says so.
_SPAWNS = re.compile(r"\bsubprocess\.|\bPopen\b|\bCLI\b|\brun_block\(|\bcross_run\.")


def pytest_collection_modifyitems(config, items):
    """Mark ``subprocess`` every test whose own code starts a process (the command lines,
    compilers, wine, qemu), so ``-m "not subprocess"`` selects the in-process tests; group
    the tests of a module-scoped fixture on one worker."""
    for item in items:
        # the tests sharing a module-scoped fixture (a docs build, a wheel build) run on one
        # xdist worker, so the fixture is made once (--dist loadgroup)
        defs = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
        if any(d[-1].scope == "module" for d in defs.values() if d):
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))
        fn = getattr(item, "function", None)
        try:
            source = inspect.getsource(fn) if fn is not None else ""
        except (OSError, TypeError):
            source = ""
        if _SPAWNS.search(source):
            item.add_marker(pytest.mark.subprocess)

# The Ctrl-C tests send SIGINT to the command lines they start. A shell that runs the test
# command in the background (``pytest &``, a CI runner without job control) starts it with
# SIGINT ignored, which every child inherits, and then no Python process sees Ctrl-C:
# restore the interactive default before any test starts a process.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def build_test_fmu(folder: str, identifier: str, version: int, out: Path,
                   description: str = "modelDescription.xml") -> Path:
    """Compile a hand-written test FMU of ``tests/data/<folder>`` (see
    :func:`testkit.handwritten.build`); skip where they cannot be built."""
    try:
        return handwritten.build(folder, identifier, version, out, description)
    except handwritten.NotBuildable as e:
        pytest.skip(str(e))


@pytest.fixture(scope="session")
def spring_damper_fmu(tmp_path_factory):
    """A third-party FMI 2.0 CS FMU, hand-written in C (tests/data/spring_damper)."""
    return build_test_fmu("spring_damper", "SpringDamper", 2, tmp_path_factory.mktemp("springdamper"))


@pytest.fixture(scope="session")
def typed_fmu(tmp_path_factory):
    """A third-party FMI 3.0 CS FMU with Float32, Int32, Boolean, Enumeration, Float64 and
    Int64 ports (tests/data/typed_feedthrough)."""
    return build_test_fmu("typed_feedthrough", "TypedFeedthrough", 3, tmp_path_factory.mktemp("typed"))


@pytest.fixture(scope="session")
def bouncing_me_fmu(tmp_path_factory):
    """A third-party FMI 2.0 Model-Exchange-only FMU with state and time events
    (tests/data/bouncing_me)."""
    return build_test_fmu("bouncing_me", "BouncingBallME", 2, tmp_path_factory.mktemp("bouncing"))


@pytest.fixture(scope="session")
def call_rules_fmu(tmp_path_factory):
    """A third-party FMI 2.0 CS FMU that logs every call, and each call the FMI standard
    forbids, to the file named by ``CALL_RULES_LOG``; it fails, crashes or hangs on
    request (tests/data/call_rules)."""
    return build_test_fmu("call_rules", "CallRules", 2, tmp_path_factory.mktemp("callrules"))


@pytest.fixture(scope="session")
def chaos_fmu(tmp_path_factory):
    """A third-party FMI 2.0 CS FMU whose calls misbehave at random by seed (Warning,
    Discard, Error, Fatal, NaN or inf outputs, a sleep, a crash), logging every call and each
    one the standard forbids to ``CHAOS_LOG`` (tests/data/chaos)."""
    return build_test_fmu("chaos", "Chaos", 2, tmp_path_factory.mktemp("chaos"))


@pytest.fixture(scope="session")
def clock_lab_fmu(tmp_path_factory):
    """A third-party FMI 3.0 FMU (ME, CS with Event Mode, SE) with clocks of every kind that
    checks the clock call rules it receives (tests/data/clock_lab)."""
    return build_test_fmu("clock_lab", "ClockLab", 3, tmp_path_factory.mktemp("clocklab"))


@pytest.fixture(scope="session")
def clock_loop_fmus(tmp_path_factory):
    """Three third-party FMI 3.0 FMUs of a clocked control loop (tests/data/clock_loop): a
    Model Exchange plant, a Model Exchange supervisor whose state event ticks an output clock,
    a Co-Simulation controller with a sample clock and a triggered mode clock:
    {"plant" | "supervisor" | "controller": path}."""
    out = tmp_path_factory.mktemp("clockloop")
    paths = {}
    for role in ("plant", "supervisor", "controller"):
        (out / role).mkdir()
        paths[role] = build_test_fmu("clock_loop", "ClockLoop", 3, out / role, f"{role}.xml")
    return paths


@pytest.fixture(scope="session")
def fmu_builds(tmp_path_factory):
    """Both plant FMUs in FMI 2.0 and 3.0, built once per session: {(name, version): path}."""
    from fmu_models import build_fmu, model_names

    paths = {}
    for version in (2, 3):
        out = tmp_path_factory.mktemp(f"fmi{version}")
        for name in model_names():
            paths[name, version] = str(build_fmu(name, out, fmi_version=version))
    return paths


@pytest.fixture(scope="session")
def fmu_paths(fmu_builds):
    """The FMI 2.0 plant FMUs: {model name: path}."""
    return {name: p for (name, v), p in fmu_builds.items() if v == 2}
