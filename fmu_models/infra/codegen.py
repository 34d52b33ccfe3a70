"""CasADi's generated C with its ``fmin`` and ``fmax`` helpers inlined, bit for bit as the C library
computes them (why and how: the user guide's page "Plant FMUs", section "What is inside").
"""
from __future__ import annotations

import re
from pathlib import Path

__all__ = ["inline_min_max", "inline_min_max_file"]

_HELPER = re.compile(r"^casadi_real casadi_(?P<op>fmin|fmax)\(casadi_real x, casadi_real y\) \{\n.*?^\}\n",
                     re.M | re.S)
_BODY = {"fmin": "y < x", "fmax": "y > x"}


def _inline(match: re.Match) -> str:
    op = match["op"]
    # ``y < x ? y : x`` is x86-64's minsd (maxsd for ``>``): x where y is NaN or equal to x;
    # only an x that is NaN against a y that is not needs the second test.
    return (f"static inline casadi_real casadi_{op}(casadi_real x, casadi_real y) {{\n"
            f"  /* C99 {op} without the library call: a NaN loses; of equal values, x (as glibc) */\n"
            f"  casadi_real m = {_BODY[op]} ? y : x;\n"
            f"  return x != x && y == y ? y : m;\n}}\n")


def inline_min_max(code: str) -> str:
    """``code`` (CasADi-generated C) with ``casadi_fmin`` and ``casadi_fmax`` inline.

    Parameters
    ----------
    code : str
        The text of a C file written by ``casadi.CodeGenerator``; each helper that is present is replaced.
    """
    return _HELPER.sub(_inline, code)


def inline_min_max_file(path: Path) -> None:
    """Rewrite the generated C file ``path`` in place with :func:`inline_min_max`."""
    path.write_text(inline_min_max(path.read_text()))
