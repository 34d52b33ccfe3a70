"""A campaign from the command line on a dask cluster started apart from it: a scheduler and
two workers on the loopback, each with a home and a temporary folder of its own (they share
no folder with the client), give the serial run's numbers exactly."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(shutil.which("dask", path=str(Path(sys.executable).parent)) is None and
                                 shutil.which("dask") is None, reason="dask.distributed is not installed")]

ARGS = ["experiment", "seed000", "--runs", "4", "--set", "duration=1", "--quiet"]


def _dask(*args) -> str:
    local = Path(sys.executable).parent / "dask"
    return [str(local) if local.exists() else "dask", *args]


def _env(folder: Path) -> dict:
    """A process of its own: its own home, temporary folder and caches."""
    for sub in ("home", "tmp", "cache"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PENDULUM_COSIM", "XDG_", "DASK_"))}
    return {**env, "HOME": str(folder / "home"), "TMPDIR": str(folder / "tmp"),
            "PENDULUM_COSIM_CACHE": str(folder / "cache"), "PYTHONWARNINGS": "ignore"}


@pytest.fixture
def cluster(tmp_path):
    info = tmp_path / "scheduler.json"
    procs = [subprocess.Popen(_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                    "--scheduler-file", str(info)), env=_env(tmp_path / "scheduler"),
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(300):
            if info.exists() and info.stat().st_size:
                break
            time.sleep(0.1)
        for w in ("w1", "w2"):
            procs.append(subprocess.Popen(_dask("worker", "--scheduler-file", str(info), "--nworkers", "1",
                                                "--nthreads", "1", "--no-dashboard",
                                                "--local-directory", str(tmp_path / w / "tmp")),
                                          env=_env(tmp_path / w), stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL))
        import json

        yield json.loads(info.read_text())["address"]
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def _run(args: list[str], out: Path, env: dict) -> pd.DataFrame:
    proc = subprocess.run([sys.executable, "-c", "import sys; from cosim.cli import main; sys.exit(main())",
                           *args, "--out", str(out)], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return pd.read_csv(out / "per_run.csv")


def test_a_campaign_on_a_cluster_started_apart_gives_the_serial_numbers(cluster, tmp_path):
    env = _env(tmp_path / "client")
    on_cluster = _run([*ARGS, "--backend", "dask", "--scheduler", cluster], tmp_path / "dask", env)
    serial = _run([*ARGS, "--backend", "serial"], tmp_path / "serial", env)
    pd.testing.assert_frame_equal(on_cluster, serial, check_exact=True)
    assert len(serial) and not list((tmp_path / "client" / "tmp").iterdir())
    # the tasks ran on the workers: they compiled the filters into their own caches
    assert any(any((tmp_path / w / "cache").iterdir()) for w in ("w1", "w2"))
