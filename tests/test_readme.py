"""The README's examples run as printed (the blocks marked ``<!-- test: NAME -->``)."""
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
CLI = [sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())"]


def blocks() -> dict[str, tuple[str, str]]:
    """name -> (language, code) of every marked block."""
    text = (ROOT / "README.md").read_text()
    found = re.findall(r"<!-- test: ([\w-]+) -->\n```(\w+)\n(.*?)```", text, flags=re.S)
    return {name: (lang, code) for name, lang, code in found}


def run_block(name: str, cwd: Path) -> str:
    lang, code = blocks()[name]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    if lang == "bash":
        out = []
        for line in code.strip().splitlines():
            args = shlex.split(line.split("#")[0])
            assert args[0] == "pendulum-cosim", line
            proc = subprocess.run([*CLI, *args[1:]], cwd=cwd, capture_output=True, text=True, env=env, timeout=600)
            assert proc.returncode == 0, proc.stderr
            out.append(proc.stdout)
        return "".join(out)
    proc = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, env=env,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_every_marked_block_is_known():
    assert set(blocks()) == {"estimators", "offline", "cosim", "writing-a-filter", "another-tool-export",
                             "another-tool-loop", "another-tool-ssp", "another-tool-fmpy-ssp",
                             "another-tool-platforms"}


@pytest.mark.parametrize("name", ["estimators", "cosim", "writing-a-filter"])
def test_api_examples_run(tmp_path, name):
    run_block(name, tmp_path)


def test_offline_example_learns_q_and_r_and_smooths(tmp_path):
    out = run_block("offline", tmp_path)
    q, r = map(float, re.search(r"learned q = (\S+), r = (\S+) in", out).groups())
    assert q == pytest.approx(1e-3, rel=0.05) and r == pytest.approx(1e-3, rel=0.05)
    filt, smooth = (list(map(float, re.findall(r"[\d.]+", line.split(":")[1])))
                    for line in out.splitlines()[1:3])
    assert all(s < f for s, f in zip(smooth, filt))
    assert (tmp_path / "filter_smoother_truth.png").stat().st_size > 10_000


def test_the_estimator_in_another_tool(tmp_path):
    run_block("another-tool-export", tmp_path)
    out = run_block("another-tool-loop", tmp_path)
    assert float(out.split("largest difference:")[1]) < 1e-12
    run_block("another-tool-ssp", tmp_path)
    run_block("another-tool-fmpy-ssp", tmp_path)


@pytest.mark.cross
def test_the_ssp_for_every_desktop_platform(tmp_path):
    import importlib.util
    import zipfile

    if importlib.util.find_spec("ziglang") is None or importlib.util.find_spec("lief") is None:
        pytest.skip("the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")
    run_block("another-tool-platforms", tmp_path)
    archive = tmp_path / "loop_ssp_all" / "seed000_cartpole.ssp"
    with zipfile.ZipFile(archive) as z:
        fmus = [n for n in z.namelist() if n.endswith(".fmu")]
        assert len(fmus) == 6
        for n in fmus:
            (tmp_path / "one.fmu").write_bytes(z.read(n))
            with zipfile.ZipFile(tmp_path / "one.fmu") as f:
                folders = {m.split("/")[1] for m in f.namelist() if m.startswith("binaries/")}
            assert folders == {"linux64", "win64", "darwin64"}, n
