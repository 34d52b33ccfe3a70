"""The command line's error table finds each estimator's truth by what it estimates, not
by the plant's name."""
import numpy as np
import pandas as pd

from cosim.cli import _rmse_table


def _frame(plant: str) -> pd.DataFrame:
    t = np.arange(5) * 0.01
    return pd.DataFrame({f"{plant}.x": t, f"{plant}.v": 2 * t, "ekf.x": t + 0.1, "ekf.v": 2 * t, "ekf.nis": t,
                         "ekf.P_x": t, "sensor.y_x": t - 0.2, "src.out": t}, index=t)


def test_the_truth_is_whatever_outputs_the_estimated_states():
    for name in ("plant", "cart"):
        table = _rmse_table(_frame(name), ["ekf"])
        assert table.loc["ekf", "x"] == np.float64(0.1) or abs(table.loc["ekf", "x"] - 0.1) < 1e-12
        assert table.loc["ekf", "v"] == 0.0
        assert abs(table.loc["raw measurement", "x"] - 0.2) < 1e-12
        assert "nis" not in table.columns and "P_x" not in table.columns


def test_an_estimator_without_a_truth_has_no_row():
    df = _frame("cart").drop(columns=["cart.v"])
    assert "ekf" not in _rmse_table(df, ["ekf"]).index
