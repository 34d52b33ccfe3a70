"""Typed value exchange with an FMU through its raw FMI functions, every argument prebuilt.

An :class:`Exchange` moves the values of a list of FMU variables between a float64
numpy array (the master's signals) and the FMU, one FMI call per variable type:
``fmi2GetReal``/``fmi2GetInteger``/``fmi2GetBoolean`` in FMI 2.0, ``fmi3GetFloat64``,
``fmi3GetFloat32``, ``fmi3GetInt8`` ... ``fmi3GetUInt64`` and ``fmi3GetBoolean`` in FMI
3.0 (Enumerations use the Integer/Int64 functions). The functions are fresh pointers
from the library without ``argtypes`` (ctypes' per-call conversion costs about 1.5 us a
call), so the call costs what the FMU costs. Integer and Boolean values are converted
exactly; a non-integral value sent to an integer variable is refused.
"""
from __future__ import annotations

import ctypes
from collections.abc import Callable, Sequence

import numpy as np

from fmu_models.errors import FMUError, InputError, TypeMismatchError

__all__ = ["Exchange", "raw_function"]

# FMI type name -> (ctypes element type, FMI function suffix)
_FMI2 = {"Real": (ctypes.c_double, "Real"), "Integer": (ctypes.c_int, "Integer"),
         "Enumeration": (ctypes.c_int, "Integer"), "Boolean": (ctypes.c_int, "Boolean")}
_FMI3 = {"Float64": (ctypes.c_double, "Float64"), "Float32": (ctypes.c_float, "Float32"),
         "Int8": (ctypes.c_int8, "Int8"), "UInt8": (ctypes.c_uint8, "UInt8"),
         "Int16": (ctypes.c_int16, "Int16"), "UInt16": (ctypes.c_uint16, "UInt16"),
         "Int32": (ctypes.c_int32, "Int32"), "UInt32": (ctypes.c_uint32, "UInt32"),
         "Int64": (ctypes.c_int64, "Int64"), "UInt64": (ctypes.c_uint64, "UInt64"),
         "Enumeration": (ctypes.c_int64, "Int64"), "Boolean": (ctypes.c_bool, "Boolean")}
_REAL = ("Real", "Float64")


def raw_function(dll, name: str):
    """A fresh pointer to ``name`` in ``dll`` returning int, with no argtypes."""
    try:
        f = getattr(dll, name)
    except AttributeError:
        raise FMUError(f"the FMU's library does not export {name}") from None
    fn = type(f).from_address(ctypes.addressof(f))
    fn.restype = ctypes.c_int
    fn.argtypes = None
    return fn


class _Group:
    """Variables of one FMI type: one call moves them all."""

    def __init__(self, ctype, positions: list[int], vrs: list[int]):
        n = len(vrs)
        self.positions = np.array(positions, dtype=np.intp)
        self.vr = (ctypes.c_uint32 * n)(*vrs)
        self.buf = (ctype * n)()
        self.view = np.ctypeslib.as_array(self.buf)
        self.n = ctypes.c_size_t(n)
        self.integral = ctype not in (ctypes.c_double, ctypes.c_float)


class Exchange:
    """Get or set a fixed list of FMU variables.

    Parameters
    ----------
    dll : ctypes.CDLL
        The FMU's library.
    instance : int
        The instance pointer.
    version : {2, 3}
        FMI version.
    variables : sequence
        fmpy ``ModelVariable`` objects, in the order of the values array.
    direction : {"get", "set"}
    fail : callable
        ``fail(what, status)`` raises the component's FMUError.

    Attributes
    ----------
    direct : bool
        True if every variable is a Float64/Real (one call, no conversion).
    """

    def __init__(self, dll, instance, version: int, variables: Sequence, direction: str,
                 fail: Callable[[str, int], None]):
        table = _FMI2 if version == 2 else _FMI3
        groups: dict[str, tuple] = {}
        for pos, v in enumerate(variables):
            if v.type not in table:
                raise TypeMismatchError(f"variable {v.name!r} of type {v.type} cannot be exchanged "
                                        f"(supported: {', '.join(table)})")
            ctype, suffix = table[v.type]
            groups.setdefault(suffix, (ctype, [], []))
            groups[suffix][1].append(pos)
            groups[suffix][2].append(v.valueReference)
        self.version, self.direction, self._fail = version, direction, fail
        self.inst = ctypes.c_void_p(instance)
        self.n = len(variables)
        self.names = [v.name for v in variables]
        self.groups = []
        for suffix, (ctype, pos, vrs) in groups.items():
            fn = raw_function(dll, f"fmi{version}{direction.capitalize()}{suffix}")
            self.groups.append((fn, f"{direction.capitalize()}{suffix}", _Group(ctype, pos, vrs)))
        self.direct = all(v.type in _REAL for v in variables)

    def _args(self, g: _Group, buf):
        if self.version == 2:
            return (self.inst, g.vr, g.n, buf)
        return (self.inst, g.vr, g.n, buf, g.n)

    def bind(self, array: np.ndarray, index) -> Callable[[], None]:
        """A call that moves the values between the FMU and ``array[index]``.

        ``index`` is a slice or an int array into the float64 ``array``. With one Real
        group and a contiguous slice the FMU reads or writes ``array`` in place.
        """
        if self.n == 0:
            return lambda: None
        fail = self._fail
        if self.direct and isinstance(index, slice) and len(self.groups) == 1:
            fn, label, g = self.groups[0]
            ptr = ctypes.cast(array.ctypes.data + 8 * index.start, ctypes.POINTER(ctypes.c_double))
            args = self._args(g, ptr)

            def call():
                st = fn(*args)
                if st > 1:
                    fail(label, st)
            return call
        idx = np.arange(len(array))[index] if isinstance(index, slice) else np.asarray(index, np.intp)
        parts = [(fn, label, g, self._args(g, g.buf), idx[g.positions]) for fn, label, g in self.groups]
        if self.direction == "get":
            def call():
                for fn, label, g, args, where in parts:
                    st = fn(*args)
                    if st > 1:
                        fail(label, st)
                    array[where] = g.view
            return call
        names = self.names

        def call():
            for fn, label, g, args, where in parts:
                src = array[where]
                if g.integral:
                    rounded = np.rint(src)
                    if not np.array_equal(rounded, src):
                        bad = int(np.flatnonzero(rounded != src)[0])
                        raise InputError(f"{names[g.positions[bad]]}: value {src[bad]} sent to an "
                                         "integer or Boolean variable is not integral")
                    g.view[:] = rounded
                else:
                    g.view[:] = src
                st = fn(*args)
                if st > 1:
                    fail(label, st)
        return call
