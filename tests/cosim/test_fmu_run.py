"""One FMU file run on its own (``run_fmu``, ``pendulum-cosim run Model.fmu``) against fmpy's
``simulate_fmu`` on every Reference FMU: Co-Simulation equal within 1e-12, Model Exchange
within fmpy's own error (no more than twice what fmpy's CVODE at the same tolerance is off
from fmpy's at 1e-10); inputs from a table, start values, chosen outputs; the command line's
files; and bad input named."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from testkit import reference_cases as rc

from cosim.cli import main
from cosim.fmu_run import open_fmu, run_fmu
from fmu_models.errors import ConfigurationError, UnknownNameError

REF = rc.reference_dir()
needs_reference = pytest.mark.skipif(REF is None, reason="the Reference FMUs are absent: set "
                                                         "PENDULUM_COSIM_REFERENCE_FMUS to their folder")


def _cases():
    from fmpy import read_model_description

    out = []
    for path in sorted(REF.glob("fmi[23]/*.fmu")) if REF else []:
        md = read_model_description(str(path))
        for iface, has in (("cs", md.coSimulation), ("me", md.modelExchange)):
            if has is not None and (path.stem, iface) not in rc.REFUSED and path.stem != "Clocks":
                out.append(pytest.param(path, iface, id=f"{path.parent.name}-{path.stem}-{iface}"))
    return out


def _columns(df: pd.DataFrame, r: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Our columns and fmpy's (array elements ``y[i]`` from fmpy's array columns)."""
    out = {}
    for c in df.columns:
        name, _, index = c.partition("[")
        if name not in r.dtype.names or r[name].dtype.kind not in "fiub":
            continue
        ref = r[name].astype(float)
        if index:
            ref = ref.reshape(len(r), -1)[:, int(index.rstrip("]")) - 1]
        out[c] = (df[c].to_numpy(float), ref)
    return out


def _exact(path, df: pd.DataFrame, kw: dict) -> dict[str, np.ndarray]:
    """The Model Exchange reference: fmpy's CVODE at 1e-10, or, where that does not reach the
    end (Roberts' 1e-5..1e8 s), an independent scipy solution of the model's equations."""
    from fmpy import simulate_fmu

    if path.stem in rc.ODES:
        case = rc.Case(path.stem, 3, "me", 0.0, float(df.index[0]), float(df.index[-1]))
        ref = rc._scipy(case, df.index.to_numpy(), 1e-10, 1e-14)
        return {c: ref[c].to_numpy() for c in df.columns}
    return {c: theirs for c, (_, theirs) in _columns(df, simulate_fmu(str(path), relative_tolerance=1e-10,
                                                                      **kw)).items()}


@needs_reference
@pytest.mark.parametrize("path, interface", _cases())
def test_run_fmu_equals_fmpy(path, interface):
    from fmpy import simulate_fmu

    df = run_fmu(path, interface=interface)
    h = float(df.index[1] - df.index[0])
    kw = dict(fmi_type="CoSimulation" if interface == "cs" else "ModelExchange", output_interval=h)
    if interface == "me":
        kw["record_events"] = False
    r = simulate_fmu(str(path), **kw)
    if df.attrs.get("stopped"):               # the FMU ended the run: the master records that instant too
        df = df.iloc[:len(r)]
    assert len(df) == len(r)
    np.testing.assert_allclose(df.index.to_numpy(), r["time"], rtol=0, atol=1e-9 * abs(r["time"][-1]))
    pairs = _columns(df, r)
    assert pairs, f"nothing compared: {list(df.columns)}"
    if interface == "cs":
        for c, (ours, theirs) in pairs.items():
            np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12, err_msg=c)
        return
    exact = _exact(path, df, kw)
    for c, (ours, theirs) in pairs.items():
        ref = exact[c]
        fmpy_error = np.max(np.abs(theirs - ref))
        assert np.max(np.abs(ours - ref)) <= 2 * fmpy_error + 1e-12 * (1 + np.max(np.abs(ref))), c


@needs_reference
def test_inputs_start_values_and_outputs(tmp_path):
    fmu = REF / "fmi3" / "Feedthrough.fmu"
    table = pd.DataFrame({"time": [0.0, 1.0, 1.0, 2.0], "Float64_continuous_input": [0.0, 2.0, 2.0, 2.0],
                          "Int32_input": [0, 0, 5, 5], "Boolean_input": [0, 1, 1, 1]})
    df = run_fmu(fmu, 2.0, step_size=0.25, inputs=table,
                 outputs=["Float64_continuous_output", "Int32_output", "Boolean_output"])
    assert list(df.columns) == ["Float64_continuous_output", "Int32_output", "Boolean_output"]
    np.testing.assert_array_equal(df["Float64_continuous_output"], np.minimum(2 * df.index.to_numpy(), 2.0))
    assert list(df["Int32_output"]) == [0, 0, 0, 0, 5, 5, 5, 5, 5]          # held, the value after the event at 1
    assert df["Int32_output"].dtype.kind == "i"


@needs_reference
def test_bad_input_is_named(tmp_path):
    fmu = REF / "fmi3" / "Feedthrough.fmu"
    with pytest.raises(UnknownNameError, match="input column 'nope' is not an input of the FMU"):
        open_fmu(fmu, inputs=pd.DataFrame({"time": [0.0], "nope": [1.0]}))
    with pytest.raises(ConfigurationError, match="'Int32_input' .* not whole numbers"):
        open_fmu(fmu, inputs=pd.DataFrame({"time": [0.0], "Int32_input": [0.5]}))
    with pytest.raises(ConfigurationError, match="stop_time 0 s must be after start_time 1 s"):
        open_fmu(fmu, 0.0, start_time=1.0)
    with pytest.raises(ConfigurationError, match="step_size"):
        open_fmu(fmu, step_size=-1)
    with pytest.raises(UnknownNameError, match="has no variable 'nope'"):
        open_fmu(fmu, start={"nope": 1})


@needs_reference
def test_the_command_line_runs_an_fmu_and_an_ssp(tmp_path, capsys):
    fmu = REF / "fmi2" / "BouncingBall.fmu"
    assert main(["run", str(fmu), "--out", str(tmp_path / "bb"), "--no-progress", "--stop-time", "1",
                 "--start", "e=0.5", "--outputs", "h"]) == 0
    df = pd.read_csv(tmp_path / "bb" / "results.csv", index_col="time")
    pd.testing.assert_frame_equal(df, run_fmu(fmu, 1.0, start={"e": 0.5}, outputs=["h"]), check_exact=True)
    assert (tmp_path / "bb" / "outputs.png").stat().st_size > 0
    assert "101 rows x 1 signals" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--start", "x"], "--start 'x': write NAME=VALUE"),
    (["--start", "x=[1,"], "is not a number, true/false or a list"),
])
@needs_reference
def test_the_command_line_names_bad_options(tmp_path, capsys, argv, message):
    assert main(["run", str(REF / "fmi2" / "BouncingBall.fmu"), "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_scenario_refuses_the_options_of_a_file_run(tmp_path, capsys):
    assert main(["run", "seed000_cartpole", "--dry-run", "--stop-time", "1"]) == 2
    assert "--stop-time: for an FMU or SSP run" in capsys.readouterr().err


def test_a_zip_that_is_neither_is_named(tmp_path, capsys):
    import zipfile

    with zipfile.ZipFile(tmp_path / "x.fmu", "w") as z:
        z.writestr("readme.txt", "hello")
    assert main(["run", str(tmp_path / "x.fmu"), "--dry-run"]) == 2
    assert "neither a modelDescription.xml (an FMU) nor a SystemStructure.ssd" in capsys.readouterr().err
