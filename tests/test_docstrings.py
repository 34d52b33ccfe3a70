"""Every public class and function documents each of its parameters (python-control style)."""
import inspect

import pytest

import estimators
import fmu_models
from cosim import (
    component,
    estimation,
    fmu_archive,
    fmu_component,
    fmu_me,
    imu,
    master,
    model_component,
    noise,
    recording,
    results,
    scenario,
    schedule,
    sensors,
    signal_fmu,
    sources,
    ssp,
)
from cosim.experiments import campaign, metrics, settings
from estimators import batch, em, fmu_export, smoother
from fmu_models import build, checks, fmu_pack, xml_writer

MODULES = (fmu_models, estimators, build, checks, fmu_pack, xml_writer, component, estimation, fmu_archive,
           fmu_component, fmu_me, imu, master, model_component, noise, recording, results, scenario, schedule,
           sensors, signal_fmu, sources, ssp, campaign, metrics, settings, batch, em, fmu_export, smoother)


def public_objects():
    for mod in MODULES:
        for name in getattr(mod, "__all__", []) or [n for n in dir(mod) if not n.startswith("_")]:
            obj = getattr(mod, name)
            if inspect.isclass(obj) or inspect.isfunction(obj):
                defined_here = obj.__module__ == mod.__name__ or hasattr(mod, "__all__")
                if defined_here and obj.__module__.split(".")[0] in ("fmu_models", "estimators", "cosim"):
                    yield f"{mod.__name__}.{name}", obj


def parameters(obj):
    fn = obj.__init__ if inspect.isclass(obj) else obj
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return []
    return [p.name for p in sig.parameters.values()
            if p.name not in ("self", "cls") and not p.name.startswith("_")
            and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]


@pytest.mark.parametrize("qualname,obj", list(public_objects()))
def test_public_parameters_are_documented(qualname, obj):
    doc = obj.__doc__ or ""
    if inspect.isclass(obj):   # parameters may be documented where __init__ is defined
        owner = next(c for c in obj.__mro__ if "__init__" in vars(c))
        doc += (owner.__doc__ or "") + (inspect.getdoc(owner.__init__) or "")
    assert doc.strip(), f"{qualname} has no docstring"
    missing = [p for p in parameters(obj) if p not in doc]
    assert not missing, f"{qualname}: undocumented parameters {missing}"
