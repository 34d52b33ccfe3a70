"""Every public class and function documents each of its parameters (python-control style).

The modules are found by walking the three packages, so a new module is covered without
being listed here.
"""
import inspect

import pytest
from testkit.docstrings import public_objects


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
