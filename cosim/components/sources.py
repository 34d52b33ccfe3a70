"""Signal sources: constant, step, sine, PRBS, table (CSV or DataFrame), functions of time alone."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fmu_models.errors import ConfigurationError, UnknownNameError
from fmu_models.export.signal_fmu import SignalSpec, build_signal_fmu
from fmu_models.infra.checks import finite, positive, positive_int

from ..core.component import Component, ExportedFMU, Port, bind_protocol
from ..core.native import OP_CONST, OP_PRBS, OP_SWITCH, Op


class _Source(Component):
    """A component whose outputs depend on time only (reentrant)."""

    reentrant = True
    #: The ``_value`` methods whose arithmetic the native kernel has (as :meth:`_native_op`).
    _native_values: tuple = ()
    #: The Real parameters of the signal FMU of the source's ``kind``, ``(attribute, domain,
    #: description)``, empty for a source without an FMU form.
    _fmu_reals: tuple = ()

    def _value(self, t):
        """The outputs at ``t`` [s]."""
        raise NotImplementedError

    def _set_finite(self, **values) -> None:
        """Each of ``values`` checked finite, as the attribute of its name."""
        for key, value in values.items():
            setattr(self, key, finite(value, f"{self.name}: {key}"))

    def _fmu_ints(self) -> list[tuple]:
        """The Integer parameters of the signal FMU."""
        return []

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """This source as a signal FMU (:mod:`fmu_models.export.signal_fmu`) with output ``out``
        (``clocked``: its clocked form, FMI 3.0)."""
        if not self._fmu_reals:
            raise ConfigurationError(f"{self.name}: a {type(self).__name__} source has no FMU form")
        reals = [(key, getattr(self, key), domain, text) for key, domain, text in self._fmu_reals]
        spec = SignalSpec(self.kind, self.period, ["out"], reals=reals, ints=self._fmu_ints(),
                          description=f"{type(self).__name__} source {self.name} (pendulum-cosim)")
        path = build_signal_fmu(spec, folder, fmi_version, self._fmu_identifier(), f"{self.name}.fmu", clocked)
        return ExportedFMU(path, spec.parameters())

    def output(self, t, u):
        return np.atleast_1d(self._value(t))

    def native_reason(self) -> str | None:
        """Why this source's calls run in Python (None: in the native kernel)."""
        cls = type(self)
        if not self._native_values:
            return "a Python component"
        if (cls.output is not _Source.output or cls.update is not Component.update
                or cls._value not in self._native_values):
            return "a Python component (its own output or update)"
        return None

    def bind(self, values, inputs, outputs, integers=None):
        """The Python component's calls, which the native kernel runs itself (the same arithmetic)
        when :meth:`native_reason` is None."""
        if self.native_reason() is not None:
            return bind_protocol(self, values, values, inputs, outputs, integers)
        value = self._value

        def output_fn(t: float) -> None:
            values[outputs] = value(t)

        def update_fn(t: float) -> None:
            pass

        output_fn.native, update_fn.native = [self._native_op(outputs)], []
        return output_fn, update_fn


class Constant(_Source, kind="constant"):
    """Constant output ``value`` on port ``out``.

    Parameters
    ----------
    name : str
    period : float
        Sample period [s].
    value : float
    """

    def __init__(self, name: str, period: float, value: float):
        super().__init__(name, period, outputs=["out"])
        self._set_finite(value=value)

    def _value(self, t):
        return self.value

    _native_values = (_value,)

    def _native_op(self, outputs: slice) -> Op:
        return Op(OP_CONST, dict(slot=outputs.start, a=self.value))

    _fmu_reals = (("value", "real", "the output"),)


class Step(Constant, kind="step"):
    """``before`` until ``t_step`` [s], then ``after`` (seed 000 Figure 2's input is
    ``Step(t_step=2, before=-0.5, after=0.5)``).

    Parameters
    ----------
    name : str
    period : float
    t_step : float
        Switching time [s].
    before, after : float
        Values before and from ``t_step`` on.
    """

    def __init__(self, name: str, period: float, t_step: float, before: float, after: float):
        super().__init__(name, period, before)
        self._set_finite(t_step=t_step, after=after)
        self.before = self.value

    def _value(self, t):
        return self.after if t >= self.t_step - 1e-12 else self.before

    _native_values = (_value,)

    def _native_op(self, outputs: slice) -> Op:
        return Op(OP_SWITCH, dict(slot=outputs.start, a=self.t_step - 1e-12, b=self.before, c=self.after))

    _fmu_reals = (("t_step", "real", "switching time [s]"), ("before", "real", "output before t_step"),
                  ("after", "real", "output from t_step on"))


class Sine(_Source, kind="sine"):
    """``offset + amplitude * sin(2 pi frequency t + phase)`` on port ``out``.

    Parameters
    ----------
    name : str
    period : float
    amplitude, frequency, phase, offset : float
        Frequency [Hz], phase [rad] (default phase and offset 0).
    """

    def __init__(self, name, period, amplitude, frequency, phase=0.0, offset=0.0):
        super().__init__(name, period, outputs=["out"])
        self._set_finite(amplitude=amplitude, frequency=frequency, phase=phase, offset=offset)

    def _value(self, t):
        return self.offset + self.amplitude * np.sin(2 * np.pi * self.frequency * t + self.phase)

    _fmu_reals = (("amplitude", "real", "amplitude"), ("frequency", "real", "frequency [Hz]"),
                  ("phase", "real", "phase [rad]"), ("offset", "real", "offset"))


#: The taps of a maximal-length Fibonacci LFSR by its order.
_TAPS = {2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
         11: (11, 9), 12: (12, 11, 10, 4), 13: (13, 12, 11, 8), 14: (14, 13, 12, 2), 15: (15, 14), 16: (16, 15, 13, 4)}


def prbs_bits(order: int, seed: int, n: int) -> np.ndarray:
    """``n`` bits of the maximal-length sequence of a Fibonacci LFSR of ``order`` 2..16,
    started from state ``seed`` (non-zero, reduced modulo 2^order)."""
    if order not in _TAPS:
        raise ConfigurationError(f"PRBS order must be in 2..16, got {order}")
    state = int(seed) % (2**order) or 1
    out = np.empty(n, dtype=bool)
    for i in range(n):
        bit = sum((state >> (tp - 1)) & 1 for tp in _TAPS[order]) & 1    # the taps' XOR
        out[i] = state & 1
        state = (state >> 1) | (bit << (order - 1))
    return out


class PRBS(_Source, kind="prbs"):
    """Pseudo-random binary sequence ``offset +/- amplitude`` of a maximal-length LFSR, each
    bit held ``bit_time``; it repeats after ``2**order - 1`` bits.

    Parameters
    ----------
    name : str
    period : float
        Sample period [s].
    amplitude, offset : float
        The levels ``offset +/- amplitude`` (default offset 0).
    bit_time : float
        Duration of one bit [s].
    order, seed : int
        LFSR length, 2..16 (default 7: 127 bits), and its non-zero start state (default 1).
    """

    def __init__(self, name, period, amplitude, bit_time, order=7, seed=1, offset=0.0):
        super().__init__(name, period, outputs=["out"])
        self._set_finite(amplitude=amplitude, offset=offset)
        self.bit_time = positive(bit_time, f"{name}: bit_time")
        self.order = positive_int(order, f"{name}: order")
        self.seed = positive_int(seed, f"{name}: seed", minimum=0)
        self.bits = prbs_bits(self.order, self.seed, 2 ** self.order - 1)

    def _value(self, t):
        b = self.bits[int(np.floor(t / self.bit_time + 1e-9)) % len(self.bits)]
        return self.offset + (self.amplitude if b else -self.amplitude)

    _native_values = (_value,)

    def _native_op(self, outputs: slice) -> Op:
        bits = np.ascontiguousarray(self.bits, dtype=float)
        return Op(OP_PRBS, dict(slot=outputs.start, a=self.bit_time, b=self.offset, c=self.amplitude,
                                buf=bits.ctypes.data, n=len(bits)), (bits,))

    _fmu_reals = (("amplitude", "real", "output levels offset +/- amplitude"),
                  ("bit_time", "positive", "duration of one bit [s]"), ("offset", "real", "offset"))

    def _fmu_ints(self):
        return [("order", self.order, 2, 16, "LFSR length"),
                ("seed", self.seed % 2**self.order, 0, 2**31 - 1, "LFSR start state (the same sequence)")]


class Table(_Source, kind="table"):
    """Signals read from a table: a pandas DataFrame or a CSV file with a time column.

    Parameters
    ----------
    name : str
    period : float
    data : DataFrame or str
        Table (or CSV path) with column ``time`` [s] and one column per output port.
    interpolation : {"zoh", "linear"} or mapping
        Between rows: hold the last row (default) or interpolate linearly, for all columns or
        per column (``{column: mode}``, the others hold); the first and last rows hold outside.
    types : mapping, optional
        FMI type of a column's port (default ``"Float64"``); integer and Boolean columns must
        hold whole numbers and are held between rows.
    """

    def __init__(self, name, period, data, interpolation="zoh", types=None):
        df = self.read(data, name)
        cols = [str(c) for c in df.columns if c != "time"]
        types = dict(types or {})
        unknown = sorted(set(types) - set(cols))
        if unknown:
            raise UnknownNameError(f"{name}: types names {unknown}, not columns; columns: {', '.join(cols)}")
        super().__init__(name, period, outputs=[Port(c, types.get(c, "Float64")) for c in cols])
        modes = interpolation if isinstance(interpolation, dict) else dict.fromkeys(cols, interpolation)
        if any(m not in ("zoh", "linear") for m in modes.values()):
            raise UnknownNameError(f"{name}: interpolation must be 'zoh' or 'linear', got {interpolation!r}")
        try:
            self.t = df["time"].to_numpy(float)
            self.v = df[cols].to_numpy(float)
        except (TypeError, ValueError):
            raise ConfigurationError(f"{name}: the table must hold numbers only") from None
        if len(self.t) == 0:
            raise ConfigurationError(f"{name}: the table has no rows")
        if np.any(np.diff(self.t) < 0):
            raise ConfigurationError(f"{name}: table time must be non-decreasing")
        if not (np.all(np.isfinite(self.v)) and np.all(np.isfinite(self.t))):
            raise ConfigurationError(f"{name}: table contains NaN or inf")
        exact = [j for j, p in enumerate(self.output_ports) if p.kind != "real"]
        bad = [cols[j] for j in exact if np.any(self.v[:, j] != np.round(self.v[:, j]))]
        if bad:
            raise ConfigurationError(f"{name}: column {bad[0]!r} ({types[bad[0]]}) holds values that are not whole "
                                     "numbers")
        self.interpolation = interpolation
        self._linear = np.array([modes.get(c) == "linear" and j not in exact for j, c in enumerate(cols)])

    @staticmethod
    def read(data, name: str = "table") -> pd.DataFrame:
        """``data`` (a DataFrame, or a CSV file's path) as a DataFrame with a ``time`` column
        (errors name ``name``)."""
        try:
            df = data if isinstance(data, pd.DataFrame) else pd.read_csv(data)
        except (OSError, ValueError, pd.errors.ParserError) as e:
            raise ConfigurationError(f"{name}: cannot read the table {data}: {e}") from None
        if "time" not in df.columns:
            raise ConfigurationError(f"{name}: the table needs a 'time' column; columns are {list(df.columns)}")
        return df

    @classmethod
    def from_scenario(cls, name, table, context):
        """As the default, with ``data`` a CSV file relative to the scenario."""
        table = dict(table)
        if "data" in table:
            table["data"] = str(context.path(table["data"], f"component {name!r}: data"))
        return context.construct(cls, name, table)

    def _value(self, t):
        i = max(np.searchsorted(self.t, t + 1e-12, side="right") - 1, 0)
        y = self.v[i].copy()
        for j in np.flatnonzero(self._linear):
            y[j] = np.interp(t, self.t, self.v[:, j])
        return y
