"""CasADi's generated C, with its ``fmin`` and ``fmax`` helpers inlined.

CasADi's code generator writes ``casadi_fmin`` and ``casadi_fmax`` as external functions that
call the C library's ``fmin`` and ``fmax``: every use is two calls, one of them through the
library's procedure linkage table, and the MF-IAE filter's step makes over two hundred of
them (its fuzzy system's centroid). :func:`inline_min_max` rewrites both helpers as static
inline functions of the same values: the C99 rules (F.10.9.2) for a NaN (the other argument
is returned; NaN if both are), and, for equal arguments (``-0.0`` and ``+0.0``), the first,
as glibc's ``fmin``/``fmax`` and CasADi's own evaluation return it, so that the compiled
code and CasADi's virtual machine keep giving the same bits (tests/test_codegen.py checks
it on the special values). A signalling NaN comes back as itself rather than quietened.
Written as ``y < x ? y : x`` (``>`` for fmax), the comparison is one x86-64 ``minsd``
(``maxsd``) instruction, with one well-predicted test for a NaN ``x``; the performance page
of the manual gives what it saves.
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
        The text of a C file written by ``casadi.CodeGenerator``.

    Returns
    -------
    str
        The same text, each helper that is present replaced (one that is absent: nothing).
    """
    return _HELPER.sub(_inline, code)


def inline_min_max_file(path: Path) -> None:
    """Rewrite the generated C file ``path`` in place with :func:`inline_min_max`."""
    text = path.read_text()
    path.write_text(inline_min_max(text))
