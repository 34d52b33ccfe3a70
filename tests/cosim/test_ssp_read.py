"""SSP 1.0 as other tools write it, in the master: a nested system, connections through a
system's connectors, unit conversions and a transformation on a connection, a parameter file
(.ssv) with units and a parameter mapping (.ssm) with a transformation, names with spaces and
dots; each run equal to the same system written as a scenario; and what is still refused,
named."""
from __future__ import annotations

import logging
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim import Scenario, Step
from cosim.ssp import open_ssp, run_ssp
from fmu_models import build_fmu, get_model
from fmu_models.errors import ConfigurationError, FMUError

RIG = Path(__file__).parents[1] / "data" / "ssp_rig"
SSV = (RIG / "cart.ssv").read_text()
#: the mapping renames two parameters; the pole length's entry also scales it (and, as
#: suppressUnitConversion says, without converting its unit first): l = 0.02 * 40 - 0.4
SSM = (RIG / "cart.ssm").read_text()


def _ssd(transform: str = '<ssc:LinearTransformation factor="2" offset="0.1"/>') -> str:
    """The rig's SSD (tests/data/ssp_rig) with ``transform`` on the force's connection."""
    return (RIG / "SystemStructure.ssd").read_text().replace("TRANSFORM", transform)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    plant = build_fmu(get_model("cartpole"), folder)
    drive = Step("drive", 0.01, t_step=0.5, before=-0.5, after=0.5).export_fmu(folder).path
    return plant, drive


def _write(folder, fmus, ssd: str, archive: bool = False, ssv: str = SSV):
    res = folder / "resources"
    res.mkdir(parents=True)
    shutil.copy(fmus[0], res / "plant.fmu")
    shutil.copy(fmus[1], res / "drive.fmu")
    (res / "cart.ssv").write_text(ssv)
    (res / "cart.ssm").write_text(SSM)
    (folder / "SystemStructure.ssd").write_text(ssd)
    if not archive:
        return folder
    path = folder.parent / f"{folder.name}.ssp"
    with zipfile.ZipFile(path, "w") as z:
        for f in folder.rglob("*"):
            z.write(f, f.relative_to(folder).as_posix())
    return path


def _scenario(tmp_path, fmus, factor: float, offset: float, x: float = 0.25, after: float = 0.25,
              stop: float = 2.0) -> pd.DataFrame:
    """The same system written as a scenario: the two FMUs with the values the SSP's
    bindings give, and a conversion for the connection."""
    (tmp_path / "s.toml").write_text(f"""
[simulation]
stop_time = {stop!r}
[[component]]
name = "Drive_Unit_Force_Source"
type = "fmu"
path = "{fmus[1]}"
period = 0.01
outputs = ["out"]
parameters = {{ after = {after!r}, before = -0.0005 }}
[[component]]
name = "Cart_Pole"
type = "fmu"
path = "{fmus[0]}"
period = 0.01
inputs = ["F"]
outputs = ["x", "theta"]
parameters = {{ mc = 1.25, l = 0.4, x = {x!r} }}
[[component]]
name = "Cart_Pole_F_conversion"
type = "conversion"
period = 0.01
factor = {factor!r}
offset = {offset!r}
[connections]
"Cart_Pole_F_conversion.u" = "Drive_Unit_Force_Source.out"
"Cart_Pole.F" = "Cart_Pole_F_conversion.y"
""")
    return Scenario.load(tmp_path / "s.toml").run()


@pytest.mark.parametrize("archive", [False, True], ids=["folder", "archive"])
def test_a_nested_system_with_parameter_files_and_a_transformation_equals_its_scenario(tmp_path, fmus, archive,
                                                                                       caplog):
    path = _write(tmp_path / "rig", fmus, _ssd(), archive)
    with caplog.at_level(logging.WARNING, logger="cosim.ssp"), open_ssp(path) as system:
        assert system.names == {"Drive Unit.Force Source": "Drive_Unit_Force_Source", "Cart Pole": "Cart_Pole"}
        ssp = system.run()
        comps = system.cosim.by_name
        # the higher level's binding wins over the component's own; units converted (g -> kg)
        assert comps["Drive_Unit_Force_Source"].settings["after"] == 0.25
        assert comps["Cart_Pole"].settings["mc"] == pytest.approx(1.25, rel=0, abs=1e-15)
        assert comps["Cart_Pole"].settings["l"] == pytest.approx(0.4, rel=0, abs=1e-15)
    assert "'Cart Pole.not a variable' reaches no variable" in caplog.text
    # kN -> N first (x 1000), then the transformation (2 u + 0.1)
    scenario = _scenario(tmp_path, fmus, 2000.0, 0.1)
    for col in ("Cart_Pole.x", "Cart_Pole.theta", "Drive_Unit_Force_Source.out"):
        np.testing.assert_array_equal(ssp[col].to_numpy(), scenario[col].to_numpy())
    np.testing.assert_array_equal(ssp["Cart_Pole_F_conversion.y"], 2000 * ssp["Drive_Unit_Force_Source.out"] + 0.1)


def test_run_ssp_in_one_call_with_start_values_and_outputs(tmp_path, fmus):
    path = _write(tmp_path / "rig", fmus, _ssd(""))
    df = run_ssp(path, 1.0, start={"Cart Pole.x": 0.75, "Drive_Unit_Force_Source.after": 0.001},
                 outputs=["Cart_Pole.*"])
    assert list(df.columns) == ["Cart_Pole.x", "Cart_Pole.theta"]
    assert df["Cart_Pole.x"].iloc[0] == 0.75
    scenario = _scenario(tmp_path, fmus, 1000.0, 0.0, x=0.75, after=0.001, stop=1.0)   # the unit conversion alone
    np.testing.assert_array_equal(df.to_numpy(), scenario[df.columns].to_numpy())


@pytest.mark.parametrize("change, error, message", [
    (('<ssd:Connector name="force.out" kind="output"><ssc:Real unit="kN"/>',
      '<ssd:Connector name="force.out" kind="output"><ssc:Real unit="m"/>'),
     ConfigurationError, r"connection Force Source.out -> force.out: unit 'kN' \(kg\^1 m\^1 s\^-2\) cannot be "
                         r"converted to 'm' \(m\^1\)"),
    (('<ssc:Real unit="N"/>', '<ssc:Real unit="lbf"/>'), ConfigurationError, "names the unit 'lbf'"),
    (('source="resources/cart.ssv"', 'source="../cart.ssv"'), FMUError, "points outside the SSP"),
    (('source="resources/cart.ssv"', 'source="resources/none.ssv"'), FMUError, "is not in the SSP"),
    (('source="resources/cart.ssv"', 'source="resources/plant.fmu"'), FMUError, "not valid XML"),
    (('source="resources/cart.ssv"', 'source="https://example.org/cart.ssv"'), ConfigurationError,
     "not a relative path"),
    (('endElement="Cart Pole" endConnector="F"', 'endElement="Cart Pole" endConnector="G"'), ConfigurationError,
     "names a connector that Cart Pole does not declare"),
    (('startElement="Cart Pole" startConnector="x" endConnector="cart.x"',
      'startElement="Cart Pole" startConnector="F" endConnector="cart.x"'), ConfigurationError,
     "Cart Pole.F is an input connector; a connection starts at an output"),
    (('<ssd:Component name="Cart Pole" source="resources/plant.fmu">',
      '<ssd:Component name="Cart Pole" source="resources/plant.fmu" type="application/x-ssp-package">'),
     ConfigurationError, "is not an FMU"),
    (('<ssc:LinearTransformation factor="2" offset="0.1"/>',
      '<ssc:IntegerMappingTransformation><ssc:MapEntry source="1" target="2"/></ssc:IntegerMappingTransformation>'),
     ConfigurationError, "linear transformation or unit conversion and a mapping"),
])
def test_what_cannot_be_honoured_is_named(tmp_path, fmus, change, error, message):
    ssd = _ssd()
    assert change[0] in ssd
    path = _write(tmp_path / "rig", fmus, ssd.replace(*change))
    with pytest.raises(error, match=message), open_ssp(path):
        pass


@pytest.mark.parametrize("change, message", [
    (('value="1250" unit="g"', 'value="1250" unit="t"'), "parameter 'cart mass' names the unit 't', which its "
                                                          "parameter set does not define"),
    (('<ssc:BaseUnit kg="1" factor="0.001"/>', '<ssc:BaseUnit s="1" factor="0.001"/>'),
     r"parameter 'Cart Pole.mc': unit 'g' \(s\^1\) cannot be converted to 'kg' \(kg\^1\)"),
    (('<ssv:Real value="0.25"/>', '<ssv:Real value="nan"/>'), "parameter 'x'.* must be finite"),
    (('<ssv:Real value="1"/>', '<ssv:Integer value="1.5"/>'), "'not a variable' has the value '1.5', not an integer"),
])
def test_a_parameter_file_that_cannot_be_honoured_is_named(tmp_path, fmus, change, message):
    assert change[0] in SSV
    path = _write(tmp_path / "rig", fmus, _ssd(), ssv=SSV.replace(*change))
    with pytest.raises(ConfigurationError, match=message), open_ssp(path):
        pass


def _without_step(fmu, folder):
    """A copy of ``fmu`` whose DefaultExperiment gives no step."""
    out = folder / fmu.name
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'stepSize="0.01"', b"")
            dst.writestr(item, data)
    return out


def test_a_step_from_the_caller_where_the_ssp_names_none(tmp_path, fmus):
    (tmp_path / "bare").mkdir()
    bare = (_without_step(fmus[0], tmp_path / "bare"), _without_step(fmus[1], tmp_path / "bare"))
    path = _write(tmp_path / "rig", bare, _ssd())
    with pytest.raises(ConfigurationError, match="component 'Drive Unit.Force Source': no communication step"), \
            open_ssp(path):
        pass
    with open_ssp(path, step_size=0.01) as system:
        df = system.run()
    np.testing.assert_array_equal(df["Cart_Pole.x"].to_numpy(), _scenario(tmp_path, fmus, 2000.0, 0.1)["Cart_Pole.x"])
    with open_ssp(path, communication_step=0.02, step_size=0.01) as system:
        assert {c.period for c in system.cosim.components} == {0.02}
