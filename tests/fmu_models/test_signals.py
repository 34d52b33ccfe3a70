"""Interrupt-safe temporary folders (fmu_models.infra.interrupts.private_tempdir): a Ctrl-C or
SIGTERM that arrives while the folder is being created is raised once it exists, inside
the block that removes it (tempfile.TemporaryDirectory leaves it behind then: 2 of 40
interrupted builds did, measured with tests/test_hostile_cli.py's build)."""
import os
import signal
import tempfile

import pytest

from fmu_models.infra.files import private_tempdir
from fmu_models.infra.interrupts import terminate_as_interrupt


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_the_creation_is_raised_and_the_folder_removed(tmp_path, monkeypatch, sig):
    real = tempfile.mkdtemp
    made = []

    def mkdtemp_then_signal(**kw):
        path = real(**kw)
        made.append(path)
        os.kill(os.getpid(), sig)           # arrives after the folder exists, before it is returned
        return path

    monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp_then_signal)
    body = []
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        with private_tempdir("probe_", dir=tmp_path):
            body.append(1)
    assert made and not os.path.exists(made[0]) and body == []
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler     # handlers restored


def test_an_ordinary_block_keeps_and_then_removes_its_folder(tmp_path):
    with private_tempdir("probe_", dir=tmp_path) as d:
        assert os.path.isdir(d) and os.path.basename(d).startswith("probe_")
        open(os.path.join(d, "f"), "w").close()
    assert list(tmp_path.iterdir()) == []
