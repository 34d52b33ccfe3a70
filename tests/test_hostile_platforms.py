"""The hostile user of ``--platforms`` (issue 19): bad names, the missing extra, an FMU that
cannot be rebuilt (a third-party FMU without sources, a damaged file), Ctrl-C during a
cross build. Each: one named error (or exit 130), no traceback, nothing half-written and
nothing left behind."""
from __future__ import annotations

import hashlib
import importlib.util
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
from testkit.scenario_files import component, write_scenario

from cosim.cli import main
from fmu_models.__main__ import main as fmu_main
from fmu_models.errors import FMUError
from fmu_models.export.platforms import add_platforms

needs_cross = pytest.mark.skipif(
    importlib.util.find_spec("ziglang") is None or importlib.util.find_spec("lief") is None,
    reason="the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")


def one_error(capsys, status: int, expect: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert status == 2, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and expect in lines[0], err
    return lines[0]


@pytest.mark.parametrize("command", ["export-fmu", "export-ssp"])
@pytest.mark.parametrize("value,expect", [("win32", "unknown platform(s) 'win32'"),
                                          ("", "unknown platform(s) (none given)"),
                                          ("win64,win64", "platform listed twice")])
def test_bad_platform_names_are_named_and_nothing_is_written(capsys, tmp_path, command, value, expect):
    out = tmp_path / "out"
    one_error(capsys, main([command, "seed000_cartpole", "--out", str(out), "--platforms", value]), expect)
    assert not out.exists()


def test_build_with_a_bad_platform_creates_no_folder(capsys, tmp_path):
    out = tmp_path / "a" / "b"
    one_error(capsys, fmu_main(["build", "--out", str(out), "--platforms", "macos"]), "unknown platform(s) 'macos'")
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize("argv", [["build", "--out", "{out}", "--platforms", "win64"],
                                  ["export-ssp", "seed000_cartpole", "--out", "{out}", "--platforms", "darwin"]])
def test_without_the_cross_extra_the_error_says_what_to_install(capsys, tmp_path, monkeypatch, argv):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == "ziglang" else real(n, *a))
    out = tmp_path / "new"
    args = [a.replace("{out}", str(out)) for a in argv]
    status = fmu_main(args) if argv[0] == "build" else main(args)
    one_error(capsys, status, "pip install -e '.[cross]'")
    assert not out.exists()


@needs_cross
def test_an_ssp_with_a_third_party_fmu_without_sources_is_refused_by_name(capsys, tmp_path, spring_damper_fmu):
    scen = write_scenario(tmp_path / "spring.toml", 0.1, [component("fmu", "body", 0.01, path=spring_damper_fmu)])
    before = hashlib.sha256(Path(spring_damper_fmu).read_bytes()).hexdigest()
    out = tmp_path / "ssp"
    line = one_error(capsys, main(["export-ssp", str(scen), "--out", str(out), "--platforms", "win64"]),
                     "component 'body'")
    assert "lists no C source files; it cannot be rebuilt for another platform" in line
    assert not out.exists()
    assert hashlib.sha256(Path(spring_damper_fmu).read_bytes()).hexdigest() == before   # the user's FMU


@pytest.mark.parametrize("content,expect", [(None, "not a readable FMU"), (b"garbage", "not a readable FMU"),
                                            ("no-description", "no readable modelDescription.xml")])
def test_a_missing_or_damaged_fmu_is_named(tmp_path, content, expect):
    fmu = tmp_path / "x.fmu"
    if content == "no-description":
        with zipfile.ZipFile(fmu, "w") as z:
            z.writestr("sources/a.c", "int a;")
    elif content is not None:
        fmu.write_bytes(content)
    before = fmu.read_bytes() if fmu.exists() else None
    with pytest.raises(FMUError, match=expect):
        add_platforms(fmu, ["win64"])
    assert (fmu.read_bytes() if fmu.exists() else None) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ([] if content is None else ["x.fmu"])


@pytest.mark.slow
@needs_cross
def test_ctrl_c_during_a_cross_build_leaves_no_fmu_no_compiler_and_no_temporary_file(tmp_path):
    out, tmp, cache = tmp_path / "fmus", tmp_path / "tmp", tmp_path / "cache"
    tmp.mkdir()
    # nothing cached, zig's cache cold too: the compilers would run for a minute or more
    env = {**os.environ, "PENDULUM_COSIM_CACHE": str(cache), "TMPDIR": str(tmp),
           "ZIG_GLOBAL_CACHE_DIR": str(tmp_path / "zig-cache")}
    proc = subprocess.Popen([sys.executable, "-m", "fmu_models", "build", "--out", str(out), "--platforms",
                             "win64,darwin,aarch64-linux", "--fmi-version", "3"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not list(tmp.glob("pendulum_cosim_zig_*")):
        time.sleep(0.05)                                   # until zig runs
    assert list(tmp.glob("pendulum_cosim_zig_*")), "the cross build did not start"
    time.sleep(1.0)                                        # the compilers are at work
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert time.monotonic() - t0 < 10, "the running compilers were not ended at once"
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert not out.exists() or not any(out.iterdir())      # no FMU without its platforms
    assert list(tmp.iterdir()) == []
    ps = subprocess.run(["ps", "-eo", "pid,args"], capture_output=True, text=True).stdout
    assert str(tmp) not in ps
