"""Typed value exchange with an FMU through its raw FMI functions, every argument prebuilt: one call
per FMI type, integers exact (int64; a UInt64 as its bit pattern) and never wrapped."""
from __future__ import annotations

import ctypes
from collections.abc import Callable, Sequence
from itertools import accumulate

import numpy as np

from fmu_models.errors import FMUError, InputError, TypeMismatchError

from ..core.native import OP_GET, OP_SET, Op
from .ports import INTEGER_RANGES, REAL_TYPES, ElementPort, integer_range

__all__ = ["FMI_TYPES", "Exchange", "raw_function"]

_FMI2 = {"Real": (ctypes.c_double, "Real"), "Integer": (ctypes.c_int, "Integer"),
         "Enumeration": (ctypes.c_int, "Integer"), "Boolean": (ctypes.c_int, "Boolean")}
#: The ctypes element type and the FMI function suffix of each FMI type name, by FMI version.
FMI_TYPES = {
    1: {**_FMI2, "Boolean": (ctypes.c_int8, "Boolean")},          # fmiBoolean is a char
    2: _FMI2,
    3: {"Float64": (ctypes.c_double, "Float64"), "Float32": (ctypes.c_float, "Float32"),
        **{t: (getattr(ctypes, f"c_{t.lower()}"), t) for t in INTEGER_RANGES if t not in ("Integer", "Boolean")},
        "Enumeration": (ctypes.c_int64, "Int64"), "Boolean": (ctypes.c_bool, "Boolean")},
}


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
    """The variables of one FMI type: one call ``fn(*args)`` (``label`` in messages) moves them
    all (every element of an array)."""

    def __init__(self, fn, label: str, ctype, type_name: str, ports: list[tuple[int, ElementPort]], inst, version):
        sizes = {p.variable.valueReference: p.size for _, p in ports}       # in order of appearance
        variables = list(sizes)
        base = dict(zip(variables, accumulate(sizes.values(), initial=0)))
        self.n_values = sum(sizes.values())
        self.positions = np.array([pos for pos, _ in ports], dtype=np.intp)      # in the port list
        self.offsets = np.array([base[p.variable.valueReference] + p.offset for _, p in ports], dtype=np.intp)
        self.vr = (ctypes.c_uint32 * len(variables))(*variables)
        self.n_vr = ctypes.c_size_t(len(variables))
        self.n = ctypes.c_size_t(self.n_values)
        self.buf = (ctype * max(self.n_values, 1))()
        self.fn, self.label, self.args = fn, label, self.args_with(inst, version, self.buf)
        self.view = np.ctypeslib.as_array(self.buf)[: self.n_values]
        #: the ports are the group's values in order (no gather needed)
        self.identity = bool(np.array_equal(self.offsets, np.arange(self.n_values)))
        self.type_name = type_name
        self.real = type_name in REAL_TYPES
        self.boolean = type_name == "Boolean"
        self.unsigned64 = type_name == "UInt64"
        self.ports = [p for _, p in ports]

    def args_with(self, inst, version: int, buf) -> tuple:
        """The arguments of the call for the instance ``inst`` moving the values in ``buf``."""
        return (inst, self.vr, self.n_vr, buf) + ((self.n,) if version == 3 else ())


class Exchange:
    """Get or set a fixed list of element ports.

    Parameters
    ----------
    instance : FMUInstance
        The FMU instance (:mod:`cosim.fmi.instance`): its functions, pointer, FMI version, name
        and ``fail(what, status)``, which raises its FMUError.
    ports : sequence of ElementPort
        In the order of the index given to :meth:`bind`.
    direction : {"get", "set"}
    sources : sequence of (str, str), optional
        For ``"set"``: each port's source signal name and FMI type (default: unknown, signed).

    Attributes
    ----------
    direct : bool
        True if every port is a scalar Float64/Real of its own value reference (one call,
        no conversion, no copy).
    """

    def __init__(self, instance, ports: Sequence[ElementPort], direction: str,
                 sources: Sequence[tuple[str, str]] | None = None):
        version = instance.version
        table = FMI_TYPES[version]
        by_suffix: dict[str, tuple] = {}
        for pos, p in enumerate(ports):
            if p.type not in table:
                raise TypeMismatchError(f"variable {p.name!r} of type {p.type} cannot be exchanged "
                                        f"(supported: {', '.join(table)})")
            ctype, suffix = table[p.type]
            by_suffix.setdefault(suffix, (ctype, p.type, []))[2].append((pos, p))
        self.version, self.direction, self._fail, self.owner = version, direction, instance.fail, instance.owner
        self.inst = ctypes.c_void_p(instance.handle)
        self.n = len(ports)
        self.sources = list(sources) if sources is not None else [("?", "Int64")] * len(ports)
        label = direction.capitalize()
        self.groups = [_Group(instance.raw(f"fmi{version}{label}{suffix}"), label + suffix, ctype, type_name,
                              members, self.inst, version)
                       for suffix, (ctype, type_name, members) in by_suffix.items()]
        # aliases (sharing a value reference) are one value copied to each port: not in place
        self.direct = (all(p.type in ("Real", "Float64") and p.size == 1 for p in ports)
                       and all(g.identity for g in self.groups))

    def preset(self, values_by_port: dict[str, float]) -> None:
        """Start values of array elements that no connection sets (a set sends all of an array)."""
        for g in self.groups:
            for off, p in zip(g.offsets, g.ports):
                if p.name in values_by_port:
                    g.view[off] = values_by_port[p.name]

    def bind(self, values: np.ndarray, index, integers: np.ndarray | None = None,
             changes: bool = False) -> Callable[[], bool | None]:
        """A call that moves the values between the FMU and ``values[index]`` (floats) and, for
        integer and Boolean ports, ``integers[index]`` (exact int64); ``index`` a slice (the FMU
        works in ``values`` in place if it can) or an int array. With ``changes`` (a setter),
        the call returns whether a value differs from the one set before (an input that jumped)."""
        if self.n == 0:
            return no_exchange
        fail = self._fail
        if self.direct and isinstance(index, slice) and len(self.groups) == 1 and not changes:
            g = self.groups[0]
            fn, label, address = g.fn, g.label, values.ctypes.data + 8 * index.start
            args = g.args_with(self.inst, self.version, ctypes.cast(address, ctypes.POINTER(ctypes.c_double)))

            def call():
                st = fn(*args)
                if st > 1:
                    fail(label, st)
            call.native = [self._op(g, address, None, values)]
            return call
        if integers is None:
            integers = np.zeros(len(values), dtype=np.int64)
        idx = np.arange(len(values))[index]
        parts = [(g.fn, g.label, g, g.args, idx[g.positions]) for g in self.groups]
        call = (self._getter(parts, values, integers) if self.direction == "get"
                else self._setter(parts, values, integers, changes))
        if not changes and all(g.type_name in ("Real", "Float64") for g in self.groups):
            call.native = [self._op(g, ctypes.addressof(g.buf), where, values) for _, _, g, _, where in parts]
        return call

    def _op(self, g: _Group, buf: int, where, values):
        """The native kernel's operation of ``g``'s call on ``buf``, ``where`` each port's signal (None: in place)."""
        fail, label = self._fail, g.label
        if where is None:
            idx = off = np.zeros(0, np.int64)
        else:
            idx, off = np.ascontiguousarray(where, np.int64), np.ascontiguousarray(g.offsets, np.int64)
        fields = dict(fn=ctypes.cast(g.fn, ctypes.c_void_p).value, inst=self.inst.value, vr=ctypes.addressof(g.vr),
                      nvr=g.n_vr.value, nbuf=-1 if self.version < 3 else g.n.value, buf=buf, n=len(idx),
                      idx=idx.ctypes.data, off=off.ctypes.data)
        return Op(OP_GET if self.direction == "get" else OP_SET, fields, (g, idx, off, values),
                  lambda op, t: fail(label, op.status))

    def _getter(self, parts, values, integers):
        fail = self._fail

        def call():
            for fn, label, g, args, where in parts:
                st = fn(*args)
                if st > 1:
                    fail(label, st)
                vals = g.view if g.identity else g.view[g.offsets]
                values[where] = vals
                if not g.real:
                    integers[where] = vals.view(np.int64) if g.unsigned64 else vals.astype(np.int64)
        return call

    def _setter(self, parts, values, integers, changes: bool):
        plans = [(fn, label, g, args, where, g.offsets, self._range_plan(g)) for fn, label, g, args, where in parts]
        owner, sources, fail = self.owner, self.sources, self._fail

        def new_values(g, where, plan):
            if g.real:
                return values[where]
            src = integers[where]
            if plan is not None:
                _check_range(src, plan, g, owner, sources)
            return src.view(np.uint64) if g.unsigned64 else (src != 0 if g.boolean else src)

        def call():
            changed = False
            for fn, label, g, args, where, offs, plan in plans:
                new = new_values(g, where, plan)
                if changes and not changed:
                    changed = not np.array_equal(g.view[offs], new)
                g.view[offs] = new
                st = fn(*args)
                if st > 1:
                    fail(label, st)
            return changed

        def differs() -> bool:
            """Whether a call now would change a value (no FMI call is made)."""
            return any(not np.array_equal(g.view[offs], new_values(g, where, plan))
                       for _, _, g, _, where, offs, plan in plans)

        call.differs = differs
        return call

    def _range_plan(self, g: _Group):
        """What a set of group ``g`` must check: None if every source's range fits the
        destination's ``[lo, hi]``, else ``(positions, unsigned, lo, hi)``: the group positions
        whose source may not fit, signed ones first, and which of them are UInt64 sources (their
        bit pattern in int64)."""
        if g.real:
            return None
        lo, hi = integer_range(g.type_name, self.version)
        checks = []
        for k, pos in enumerate(g.positions):
            _, src_type = self.sources[pos]
            try:
                lo_s, hi_s = integer_range(src_type, self.version)
            except KeyError:            # a source of another kind (a Python component's float)
                lo_s, hi_s = -2**63, 2**63 - 1
            if not (lo <= lo_s and hi_s <= hi):
                checks.append((src_type == "UInt64", k))
        if not checks:
            return None
        unsigned, positions = zip(*sorted(checks))
        return np.array(positions, np.intp), np.array(unsigned), lo, hi


def no_exchange() -> bool:
    """The exchange of no port."""
    return False


no_exchange.differs = no_exchange
no_exchange.native = []


def _check_range(src: np.ndarray, plan, g: _Group, owner: str, sources) -> None:
    positions, unsigned, lo, hi = plan
    values = src[positions]
    out = np.where(unsigned, values.view(np.uint64) > np.uint64(hi),
                     (values < np.int64(lo)) | (values > np.int64(min(hi, 2**63 - 1))))
    bad = np.flatnonzero(out)
    if len(bad):
        i = bad[0]
        k, value = int(positions[i]), int(values[i].view(np.uint64) if unsigned[i] else values[i])
        src_name, src_type = sources[g.positions[k]]
        raise InputError(f"{owner}.{g.ports[k].name} ({g.type_name}, range [{lo}, {hi}]) cannot take {value} from "
                         f"{src_name} ({src_type}): it does not fit (a value is never wrapped)")
