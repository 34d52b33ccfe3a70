"""CasADi's generated C with ``fmin``/``fmax`` inlined gives the bits of CasADi's own
evaluation (the library's ``fmin``/``fmax``) on every special value: signed zeros, NaN,
infinities, subnormals."""
from __future__ import annotations

import itertools

import casadi as ca
import numpy as np

from fmu_models.infra.codegen import inline_min_max
from fmu_models.infra.compiler import find_compiler, run_compiler

SPECIAL = [0.0, -0.0, 1.0, -1.0, np.nan, -np.nan, np.inf, -np.inf, 5e-324, -5e-324, 1e308, 2.5, 2.5000000000000004]


def _function() -> ca.Function:
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    return ca.Function("mm", [x, y], [ca.fmin(x, y), ca.fmax(x, y), ca.fmax(ca.fmin(x, 1.0), -y)])


def test_the_helpers_are_replaced_by_static_inline_ones():
    cg = ca.CodeGenerator("mm.c")
    cg.add(_function())
    code = cg.dump()
    assert "return fmin(x, y);" in code and "return fmax(x, y);" in code      # what CasADi writes
    out = inline_min_max(code)
    assert "return fmin(x, y);" not in out and "return fmax(x, y);" not in out
    assert out.count("static inline casadi_real casadi_") == 2
    assert inline_min_max("int f(void) { return 0; }\n") == "int f(void) { return 0; }\n"


def test_inlined_code_gives_casadis_bits_on_special_values(tmp_path):
    f = _function()
    cg = ca.CodeGenerator("mm.c")
    cg.add(f)
    source = tmp_path / "mm.c"
    source.write_text(inline_min_max(cg.dump()))
    lib = tmp_path / "mm.so"
    run_compiler([find_compiler(), "-O2", "-shared", "-fPIC", "-std=c99", str(source), "-o", str(lib), "-lm"],
                 "the inlined test function")
    compiled = ca.external("mm", str(lib))
    rng = np.random.default_rng(7)
    pairs = list(itertools.product(SPECIAL, repeat=2)) + [tuple(v) for v in rng.normal(size=(200, 2))]
    for x, y in pairs:
        want = np.array([float(v) for v in f(x, y)])
        got = np.array([float(v) for v in compiled(x, y)])
        nan = np.isnan(want)                    # a NaN's sign and payload aside: the same bits
        assert np.array_equal(np.isnan(got), nan), (x, y, want, got)
        assert np.array_equal(want[~nan].view(np.int64), got[~nan].view(np.int64)), (x, y, want, got)
