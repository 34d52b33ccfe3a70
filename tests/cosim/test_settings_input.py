"""Experiment settings of the right outer type but the wrong shape inside, and ``--set``
values nested too deep, are refused naming the setting."""
from __future__ import annotations

import pytest

from cosim.cli import main


@pytest.mark.parametrize("value, expect", [
    ("[1]", "scenarios = [1]"),
    ('[[1, "a"]]', 'scenarios = [[1, "a"]]'),
    ("[[1, 2, 3]]", "scenarios must be pairs of positive variances"),
    ("[[-1, 2]]", "scenarios must be pairs of positive variances"),
    ("[" * 5000 + "]" * 5000, "--set scenarios=...: --set value: arrays or tables nested more than 64 deep"),
])
def test_a_malformed_setting_is_named(tmp_path, capsys, value, expect):
    out = tmp_path / "out"
    status = main(["experiment", "seed000", "--runs", "2", "--out", str(out), "--quiet", "--set",
                   f"scenarios={value}"])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("error: ") and expect in err, err
    assert "Traceback" not in err and not out.exists()
