"""The pendulum-cosim command line."""
import os

import pandas as pd
import pytest

from cosim.cli import main


def test_help_explains_the_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for word in ("demo", "run", "scenarios", "models"):
        assert word in out


def test_demo_writes_results_table_and_plot(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "RMSE against the plant's true states" in out and "mfiae" in out
    df = pd.read_csv(tmp_path / "results.csv", index_col="time")
    assert len(df) == 501 and "ekf.theta" in df.columns and "plant.theta" in df.columns
    assert (tmp_path / "results.parquet").exists() and (tmp_path / "truth_vs_estimate.png").stat().st_size > 10_000
    umask = os.umask(0)
    os.umask(umask)
    for f in ("results.csv", "results.parquet", "truth_vs_estimate.png", "fmus/fmi2/CartPole.fmu"):
        assert (tmp_path / f).stat().st_mode & 0o777 == 0o666 & ~umask, f     # as any new file, not 0600
    rmse = pd.read_csv(tmp_path / "rmse.csv", index_col=0)
    # the EKF beats the raw measurements on both measured states
    assert rmse.loc["ekf", "x"] < rmse.loc["raw measurement", "x"]
    assert rmse.loc["ekf", "theta"] < rmse.loc["raw measurement", "theta"]


def test_run_shipped_wheel_pendulum_scenario_balances(tmp_path, capsys):
    assert main(["run", "seed002_wheel_lqr", "--out", str(tmp_path)]) == 0
    df = pd.read_csv(tmp_path / "results.csv", index_col="time")
    late = df.loc[2.0:]
    assert late["plant.alpha"].abs().max() < 0.02                 # balanced upright
    assert late["ekf.bias_y_alpha_dot"].mean() == pytest.approx(0.05, rel=0.15)   # gyro offset found


def test_bad_scenario_is_reported(tmp_path, capsys):
    assert main(["run", "nope", "--out", str(tmp_path)]) == 2
    assert "no scenario, FMU or SSP file 'nope'" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[simulation]\nstop_time = 1\n[[component]]\nname = \"a\"\ntype = \"constant\"\n"
                   "period = 0.1\nvalue = 1\n[connections]\n\"a.b\" = \"c.d\"\n")
    assert main(["run", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unknown component 'c'" in capsys.readouterr().err


def test_run_engine_option_gives_the_same_results_and_is_checked(tmp_path, capsys):
    """--engine replaces the scenario's [simulation] engine: python and native give the same
    file; native is refused (a named error, no traceback, --out untouched) where the kernel
    cannot run the scenario; a bad choice is refused by the parser."""
    for engine in ("python", "native"):
        assert main(["run", "seed000_cartpole", "--engine", engine, "--no-progress",
                     "--out", str(tmp_path / engine)]) == 0
    a, b = (pd.read_csv(tmp_path / e / "results.csv") for e in ("python", "native"))
    assert a.equals(b)
    assert main(["run", "seed000_cartpole", "--engine", "python", "--dry-run"]) == 0
    assert "every call runs in Python (engine='python')" in capsys.readouterr().out
    jacobi = tmp_path / "jacobi.toml"
    jacobi.write_text("[simulation]\nstop_time = 1\norder = \"jacobi\"\n[[component]]\nname = \"a\"\n"
                      "type = \"constant\"\nperiod = 0.1\nvalue = 1\n")
    assert main(["run", str(jacobi), "--engine", "native", "--out", str(tmp_path / "j")]) == 2
    err = capsys.readouterr().err
    assert "engine='native' cannot run this co-simulation" in err and "Traceback" not in err
    assert not (tmp_path / "j").exists()
    with pytest.raises(SystemExit):
        main(["run", "seed000_cartpole", "--engine", "fast", "--dry-run"])
