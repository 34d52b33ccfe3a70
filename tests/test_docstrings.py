"""Every public class and function documents each of its parameters (python-control style).

The modules are found by walking the three packages, so a new module is covered without
being listed here.
"""
import importlib
import inspect
import pkgutil

import pytest

PACKAGES = ("fmu_models", "estimators", "cosim")


def modules():
    for pkg_name in PACKAGES:
        pkg = importlib.import_module(pkg_name)
        yield pkg
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{pkg_name}."):
            if info.name.endswith("__main__"):
                continue
            yield importlib.import_module(info.name)


def public_objects(private_modules: bool = True):
    """``(qualified name, object)`` of every public class and function (also those of private
    modules such as ``estimators._fold`` unless ``private_modules`` is False)."""
    seen = set()
    for mod in modules():
        if not private_modules and any(part.startswith("_") for part in mod.__name__.split(".")):
            continue
        names = getattr(mod, "__all__", None)
        if names is None:
            names = [n for n in dir(mod) if not n.startswith("_")]
        for name in names:
            obj = getattr(mod, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            if obj.__module__.split(".")[0] not in PACKAGES or obj.__name__.startswith("_"):
                continue
            key = (obj.__module__, obj.__qualname__)
            if key not in seen:
                seen.add(key)
                yield f"{obj.__module__}.{obj.__qualname__}", obj


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
