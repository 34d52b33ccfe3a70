"""FMU binaries for Windows, macOS and aarch64 Linux (issue 19), verified, not assumed.

Cross-built with zig (the ``cross`` extra) from the FMU's own sources, then: fmpy's
validate_fmu; every binary's exports, imports and architecture read with lief; the
Windows DLL run under wine and the aarch64-linux library under qemu-user by a small FMI
driver (tests/data/cross_harness/harness.c) cross-compiled with the same compiler, against
the linux64 library driven by the same program built with gcc, over 100 steps of both
plants and the EKF FMU, and over 100 activations of a clocked EKF FMU in Scheduled
Execution. macOS code cannot run here: its files are checked statically
(universal header, architectures, exports, libSystem only, the Apple-silicon signature).
"""
from __future__ import annotations

import importlib.util
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from testkit import cross_run

from fmu_models import build_fmu, get_model
from fmu_models.errors import CompilerNotFoundError, ConfigurationError, FMUError
from fmu_models.export.platforms import add_platforms, check_binary, parse_platforms

pytestmark = pytest.mark.cross
WINE, QEMU, ARM_ROOT = cross_run.WINE, cross_run.QEMU, cross_run.ARM_ROOT
ALL = ["linux64", "win64", "darwin", "aarch64-linux"]

needs_cross = pytest.mark.skipif(
    importlib.util.find_spec("ziglang") is None or importlib.util.find_spec("lief") is None,
    reason="the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")


def test_platform_names_are_checked():
    assert parse_platforms("linux64, win64") == ("linux64", "win64")
    with pytest.raises(ConfigurationError, match="unknown platform.*'win32'.*choose from linux64, win64"):
        parse_platforms("win32")
    with pytest.raises(ConfigurationError, match="listed twice"):
        parse_platforms("win64,win64")


def test_without_the_extra_the_option_says_what_to_install(monkeypatch, tmp_path):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == "ziglang" else real(n, *a))
    fmu = build_fmu("cartpole", tmp_path)
    before = fmu.read_bytes()
    with pytest.raises(CompilerNotFoundError, match=r"ziglang.*pip install -e '\.\[cross\]'"):
        add_platforms(fmu, ["win64"])
    assert fmu.read_bytes() == before


@pytest.fixture(scope="module")
def cross_fmus(tmp_path_factory):
    """The two plants and the EKF FMU, FMI 2.0 and 3.0, with every platform's binary."""
    if importlib.util.find_spec("ziglang") is None or importlib.util.find_spec("lief") is None:
        pytest.skip("the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")
    from estimators import EKF, discretize
    from estimators.filter_fmu import export_filter_fmu

    out = tmp_path_factory.mktemp("cross")
    fmus, notes = {}, {}
    cp = discretize(get_model("cartpole"), 0.01)
    for v in (2, 3):
        for name in ("cartpole", "iwp"):
            fmus[name, v] = build_fmu(name, out / f"v{v}", fmi_version=v)
        fmus["ekf", v] = export_filter_fmu(EKF(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1), out / f"v{v}",
                                           fmi_version=v, name="ekf")
        for key in [k for k in fmus if k[1] == v]:
            notes[key] = add_platforms(fmus[key], ALL)
    return fmus, notes


@needs_cross
def test_cross_built_fmus_are_laid_out_as_the_standard_asks_and_validate(cross_fmus):
    fmus, notes = cross_fmus
    for (name, v), fmu in fmus.items():
        names = set(zipfile.ZipFile(fmu).namelist())
        ident = read_model_description(str(fmu)).coSimulation.modelIdentifier
        folders = ({"linux64": ".so", "win64": ".dll", "darwin64": ".dylib"} if v == 2 else
                   {"x86_64-linux": ".so", "x86_64-windows": ".dll", "x86_64-darwin": ".dylib",
                    "aarch64-darwin": ".dylib", "aarch64-linux": ".so"})
        assert {n for n in names if n.startswith("binaries/")} == {f"binaries/{f}/{ident}{s}"
                                                                   for f, s in folders.items()}
        assert validate_fmu(str(fmu)) == [], fmu
        assert (notes[name, v] != []) == (v == 2)                    # FMI 2.0: no aarch64-linux folder
        assert all("aarch64-linux" in n for n in notes[name, v])


@needs_cross
def test_every_binary_exports_the_fmi_functions_alone_and_links_only_system_libraries(cross_fmus, tmp_path):
    fmus, _ = cross_fmus
    expect = {"linux64": ("ELF", ["x86_64"]), "x86_64-linux": ("ELF", ["x86_64"]), "win64": ("PE", ["x86_64"]),
              "x86_64-windows": ("PE", ["x86_64"]), "darwin64": ("MachO", ["x86_64", "aarch64"]),
              "x86_64-darwin": ("MachO", ["x86_64"]), "aarch64-darwin": ("MachO", ["aarch64"]),
              "aarch64-linux": ("ELF", ["aarch64"])}
    checked = 0
    for (name, v), fmu in fmus.items():
        with zipfile.ZipFile(fmu) as z:
            for n in [n for n in z.namelist() if n.startswith("binaries/")]:
                folder = n.split("/")[1]
                lib = tmp_path / f"{name}{v}-{folder}-{Path(n).name}"
                lib.write_bytes(z.read(n))
                fmt, archs = expect[folder]
                check = check_binary(lib, v, fmt, archs)
                assert check.problems == (), (n, check.problems)
                assert len(check.exports) == (44 if v == 2 else 75)
                checked += 1
                if folder == "darwin64":                         # the universal header, by hand
                    head = lib.read_bytes()[:8]
                    assert head[:4] == b"\xca\xfe\xba\xbe" and int.from_bytes(head[4:], "big") == 2
    assert checked == 3 * 3 + 3 * 5


@needs_cross
def test_check_binary_finds_a_foreign_export_and_a_wrong_architecture(cross_fmus, tmp_path):
    fmus, _ = cross_fmus
    with zipfile.ZipFile(fmus["cartpole", 3]) as z:
        lib = tmp_path / "CartPole.so"
        lib.write_bytes(z.read("binaries/aarch64-linux/CartPole.so"))
    check = check_binary(lib, 3, "ELF", ["x86_64"])
    assert any("architectures aarch64, expected x86_64" in p for p in check.problems)
    check = check_binary(lib, 2, "ELF", ["aarch64"])                 # an FMI 3.0 library as FMI 2.0
    assert any("missing FMI functions" in p for p in check.problems)
    junk = tmp_path / "junk.so"
    junk.write_bytes(b"not a library")
    with pytest.raises(FMUError, match="not a readable shared library"):
        check_binary(junk, 2, "ELF", ["x86_64"])


@needs_cross
def test_an_fmu_without_sources_is_refused_and_left_as_it_was(cross_fmus, tmp_path):
    fmus, _ = cross_fmus
    stripped = tmp_path / "nosrc.fmu"
    with zipfile.ZipFile(fmus["iwp", 2]) as z, zipfile.ZipFile(stripped, "w") as o:
        for n in z.namelist():
            if not n.startswith("sources/") and not n.startswith("binaries/win64"):
                o.writestr(n, z.read(n))
    before = stripped.read_bytes()
    with pytest.raises(FMUError, match="not in its sources/ folder"):
        add_platforms(stripped, ["win64"])
    assert stripped.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nosrc.fmu"]


# ---------------------------------------------------------------------------- running them
def skip_without_runner(platform: str) -> None:
    """Skip, with the reason, where the program that runs ``platform``'s code is missing."""
    if platform == "win64" and WINE is None:
        pytest.skip("wine64 is not installed (Debian: apt-get install wine64); .ci/run installs it")
    if platform == "aarch64-linux" and (QEMU is None or not (ARM_ROOT / "lib").is_dir()):
        pytest.skip("qemu-user and libc6-arm64-cross are not installed (Debian: apt-get install qemu-user "
                    "libc6-arm64-cross); .ci/run installs them")


@needs_cross
@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.parametrize("name", ["cartpole", "iwp", "ekf"])
def test_the_other_platforms_binaries_run_and_equal_linux64(cross_fmus, tmp_path_factory, platform, name):
    skip_without_runner(platform)
    fmus, _ = cross_fmus
    tmp = tmp_path_factory.getbasetemp() / "cross-run"
    tmp.mkdir(exist_ok=True)
    for v in ((2, 3) if platform == "win64" else (3,)):
        ref, got = cross_run.compare(fmus[name, v], v, platform, tmp)
        assert ref.shape[0] == 100 and np.isfinite(ref).all() and np.ptp(ref, axis=0).max() > 0
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * max(1.0, np.abs(ref).max()),
                                   err_msg=f"{name} FMI {v} {platform}")


@pytest.fixture(scope="module")
def clocked_ekf(tmp_path_factory):
    """The clocked EKF FMU (FMI 3.0, input clock ``sample``) with every platform's binary."""
    if importlib.util.find_spec("ziglang") is None or importlib.util.find_spec("lief") is None:
        pytest.skip("the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")
    from estimators import EKF, discretize
    from estimators.filter_fmu import export_filter_fmu

    cp = discretize(get_model("cartpole"), 0.01)
    fmu = export_filter_fmu(EKF(cp, [0.5, 0, 1.8, 0.5], 1.0, 0.2, 0.1), tmp_path_factory.mktemp("clocked"),
                            fmi_version=3, clocked=True, name="ekf")
    assert add_platforms(fmu, ["win64", "aarch64-linux"]) == []
    return fmu


def scheduled_in_fmpy(fmu: Path, folder: Path, steps: int = 100) -> np.ndarray:
    """The linux64 binary in fmpy's Scheduled Execution driver, the clocked inputs set to the
    harness's sequence before each activation at k 10 ms: the outputs after each."""
    from fmpy import extract
    from fmpy.fmi3 import FMU3ScheduledExecution

    md = read_model_description(str(fmu))
    inputs = [v.valueReference for v in md.modelVariables if v.causality == "input" and v.type == "Float64"]
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    (clock,) = [v.valueReference for v in md.modelVariables if v.type == "Clock"]
    f = FMU3ScheduledExecution(guid=md.instantiationToken, unzipDirectory=extract(str(fmu), str(folder)),
                               modelIdentifier=md.scheduledExecution.modelIdentifier, instanceName="se")
    f.instantiate()
    f.enterInitializationMode(startTime=0.0)
    f.exitInitializationMode()
    got = []
    for k in range(steps):
        f.setFloat64(inputs, [((37 * k + 11 * j) % 101 - 50) / 50.0 for j in range(len(inputs))])
        f.activateModelPartition(clock, k * 0.01)
        got.append(f.getFloat64(outputs))
    f.terminate()
    f.freeInstance()
    return np.array(got)


@needs_cross
@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
def test_a_clocked_ekf_in_scheduled_execution_gives_linux64_bits_on_the_other_platforms(
        clocked_ekf, tmp_path_factory, platform):
    """The driver's Scheduled Execution mode (instantiate, initialise, then per activation
    set the clocked inputs, fmi3ActivateModelPartition(sample, t_k), get the estimates) run on
    the Windows DLL under wine and the aarch64-linux library under qemu: bit for bit the
    linux64 library's estimates under the same driver, which are fmpy's own."""
    skip_without_runner(platform)
    tmp = tmp_path_factory.getbasetemp() / "cross-run"
    tmp.mkdir(exist_ok=True)
    ref, got = cross_run.compare(clocked_ekf, "3se", platform, tmp)
    assert ref.shape == (100, 11) and np.isfinite(ref).all() and np.ptp(ref, axis=0).min() > 0
    np.testing.assert_array_equal(ref, scheduled_in_fmpy(clocked_ekf, tmp_path_factory.mktemp("se-fmpy")))
    np.testing.assert_array_equal(got, ref, err_msg=f"clocked ekf, Scheduled Execution, {platform}")


@needs_cross
def test_the_scheduled_execution_driver_stops_at_an_error_with_the_fmus_message(clocked_ekf, tmp_path):
    """Activations every 20 ms of a clock of interval 10 ms: the second skips a tick, the FMU
    answers Error, and the driver stops there with status 4 and the FMU's reason."""
    lib = tmp_path / "ekf.so"
    with zipfile.ZipFile(clocked_ekf) as z:
        lib.write_bytes(z.read("binaries/x86_64-linux/ekf.so"))
    with pytest.raises(AssertionError, match=r"(?s)the driver failed \(4\).*skips the activation of the clock "
                                             r"sample at 0.01.*fmi3ActivateModelPartition.* returned 3"):
        cross_run.run(cross_run.harness(tmp_path, None), lib, clocked_ekf, "3se", tmp_path, steps=3, step=0.02)
