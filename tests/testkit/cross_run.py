"""Running an FMU's binary for another platform (tests/fmu_models/test_platforms.py and
bench/bench_platforms.py): the FMI driver tests/data/cross_harness/harness.c built for the
target with zig (gcc for this machine), run under wine (Windows) or qemu-user (aarch64
Linux), its printed outputs read back."""
from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
from fmpy import read_model_description

HARNESS = Path(__file__).parents[1] / "data" / "cross_harness" / "harness.c"
HEADERS = Path(fmpy.__file__).parent / "c-code"
WINE = shutil.which("wine64") or ("/usr/lib/wine/wine64" if Path("/usr/lib/wine/wine64").exists() else None)
QEMU = shutil.which("qemu-aarch64")
ARM_ROOT = Path("/usr/aarch64-linux-gnu")
#: The binaries folder of each (FMI version, platform); "native" is this machine's.
FOLDERS = {(2, "native"): "linux64", (3, "native"): "x86_64-linux", (2, "win64"): "win64",
           (3, "win64"): "x86_64-windows", (3, "aarch64-linux"): "aarch64-linux"}
TARGETS = {"win64": "x86_64-windows-gnu", "aarch64-linux": "aarch64-linux-gnu.2.17"}


def harness(tmp: Path, target: str | None) -> list[str]:
    """The driver built for zig ``target`` (None: this machine, with gcc): its command prefix."""
    from fmu_models.export.platforms import zig_command

    exe = tmp / f"harness-{target or 'native'}{'.exe' if target and 'windows' in target else ''}"
    if not exe.exists():
        cc = ["gcc"] if target is None else [*zig_command(), "-target", target, "-ffp-contract=off"]
        libs = [] if target and "windows" in target else ["-ldl"]
        subprocess.run([*cc, "-O2", "-std=c99", f"-I{HEADERS}", str(HARNESS), "-o", str(exe), *libs],
                       check=True, capture_output=True, cwd=tmp)
    if target is None:
        return [str(exe)]
    if "windows" in target:
        return [WINE, str(exe)]
    return [QEMU, "-L", str(ARM_ROOT), str(exe)]


def run(cmd: list[str], lib: Path, fmu: Path, version: int | str, tmp: Path, steps: int = 100,
        step: float = 0.01) -> np.ndarray:
    """The outputs after each of ``steps`` steps of ``step`` seconds, every Real input driven
    by the driver's exact sequence (process noise inputs scaled by 0.01). ``version`` 2 or 3:
    Co-Simulation; ``"3se"``: Scheduled Execution of a clocked FMU, its input clock's model
    partition activated every ``step`` seconds from 0 s after the clocked inputs are set."""
    md = read_model_description(str(fmu))
    token = md.guid if version == 2 else md.instantiationToken
    inputs = ",".join(f"{v.valueReference}:{0.01 if v.name.startswith('w_') else 1.0}"
                      for v in md.modelVariables if v.causality == "input" and v.type in ("Real", "Float64"))
    outputs = ",".join(str(v.valueReference) for v in md.modelVariables if v.causality == "output")
    clock = []
    if version == "3se":
        clock = [str(v.valueReference) for v in md.modelVariables if v.type == "Clock" and v.causality == "input"]
        assert len(clock) == 1, f"{fmu.name}: Scheduled Execution here needs one input clock, not {len(clock)}"
    env = {"WINEDEBUG": "-all", "WINEPREFIX": str(tmp / "wine"), "PATH": "/usr/bin:/bin", "HOME": str(tmp)}
    r = subprocess.run([*cmd, str(lib), str(version), token, str(steps), repr(step), inputs, outputs, *clock],
                       capture_output=True, text=True, env=env, timeout=300)
    if r.returncode != 0:
        raise AssertionError(f"the driver failed ({r.returncode}): {r.stderr[-2000:]}")
    return np.array([[float(x) for x in line.split()] for line in r.stdout.splitlines()])


def compare(fmu: Path, version: int | str, platform: str, tmp: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(linux64 outputs, platform outputs)`` of the FMU's two binaries under the driver
    (``version`` as in :func:`run`)."""
    md = read_model_description(str(fmu))
    ident = (md.scheduledExecution if version == "3se" else md.coSimulation).modelIdentifier
    fmi = int(str(version)[0])
    libs = {}
    with zipfile.ZipFile(fmu) as z:
        for key in ("native", platform):
            folder = FOLDERS[fmi, key]
            suffix = ".dll" if "win" in folder else ".so"
            libs[key] = tmp / f"{Path(fmu).stem}{version}-{folder}" / f"{ident}{suffix}"
            libs[key].parent.mkdir(exist_ok=True)
            libs[key].write_bytes(z.read(f"binaries/{folder}/{ident}{suffix}"))
    ref = run(harness(tmp, None), libs["native"], fmu, version, tmp)
    return ref, run(harness(tmp, TARGETS[platform]), libs[platform], fmu, version, tmp)
