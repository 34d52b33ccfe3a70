"""The co-simulation master: steps FMUs and discrete Python components, each at its own period.

Time runs on a base step ``h`` that divides every component's period (their greatest
common divisor unless given). At each base time ``t_k = t0 + k h``:

1. FMUs due at ``t_k`` publish the outputs of their previous step (they belong to
   ``t_k``);
2. *phase A*: the discrete components due at ``t_k`` are sampled, in the order they were
   given. With ``order="gauss-seidel"`` (default) each reads the newest values, so a
   component sees what components before it produced at ``t_k``; with ``"jacobi"`` all
   read the values as they were before phase A;
3. the row of all signals at ``t_k`` is recorded;
4. *phase B*: the FMUs due at ``t_k`` get their inputs (values after phase A; before it
   with Jacobi) and step over ``[t_k, t_k + period]``.

Outputs of a component are held between its samples (zero-order hold). With the order
``sensor, estimator, controller`` this is the papers' discrete-time loop:
``x_k = f(x_{k-1}, u_{k-1}) + w_{k-1}``, ``y_k = h(x_k) + v_k``, the filter predicts with
``u_{k-1}`` and updates with ``y_k``, and the controller computes ``u_k`` from the estimate.
"""
from __future__ import annotations

import math
import time
from fractions import Fraction
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

ORDERS = ("gauss-seidel", "jacobi")


class ConfigurationError(ValueError):
    """The co-simulation cannot be built as described (the message names the problem)."""


class CosimError(RuntimeError):
    """A component failed during a run (``message`` says which, when and why).

    Attributes
    ----------
    component : str
        Name of the failing component.
    time : float
        Simulation time [s] of the failure.
    results : pandas.DataFrame
        The signals recorded up to the failure.
    """

    def __init__(self, message, component, time, results):
        super().__init__(message)
        self.component, self.time, self.results = component, time, results


def _fraction(x: float) -> Fraction:
    return Fraction(x).limit_denominator(10**9)


def _split(ref: str, what: str) -> tuple[str, str]:
    if not isinstance(ref, str) or ref.count(".") != 1:
        raise ConfigurationError(f"{what} {ref!r} must be written 'component.port'")
    return tuple(ref.split("."))  # type: ignore[return-value]


class Cosimulation:
    """Couples components and runs them.

    Parameters
    ----------
    components : sequence
        :class:`~cosim.component.Component` and
        :class:`~cosim.fmu_component.FMUComponent` objects. Discrete components are
        sampled in this order.
    connections : mapping or iterable of pairs
        ``{"dst.port": "src.port"}`` or ``[("src.port", "dst.port"), ...]``: each input
        port gets at most one source. Every input of a discrete component must be
        connected; unconnected FMU inputs keep their start values.
    step_size : float, optional
        Base step [s]; every period must be an integer multiple of it. Default: the
        greatest common divisor of the periods.
    order : {"gauss-seidel", "jacobi"}
        Update order within a base step (see the module documentation).

    Raises
    ------
    ConfigurationError
        Duplicate names, an unknown component or port (the message lists the valid
        ones), an input connected twice, an unconnected required input, or a period
        that is not an integer multiple of the base step.
    """

    def __init__(self, components: Sequence, connections, step_size: float | None = None,
                 order: str = "gauss-seidel"):
        if order not in ORDERS:
            raise ConfigurationError(f"order must be one of {ORDERS}, got {order!r}")
        self.order = order
        self.components = list(components)
        names = [c.name for c in self.components]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigurationError(f"duplicate component names: {dup}")
        self.by_name = {c.name: c for c in self.components}
        self.connections = self._parse_connections(connections)
        self.step_size = self._base_step(step_size)
        self._layout()

    # ---------------------------------------------------------------- validation
    def _port(self, ref: str, direction: str):
        comp, port = _split(ref, f"{direction} port")
        if comp not in self.by_name:
            raise ConfigurationError(f"unknown component {comp!r} in {ref!r}; components: "
                                     f"{', '.join(self.by_name)}")
        c = self.by_name[comp]
        ports = c.output_names if direction == "output" else c.input_names
        if port not in ports:
            raise ConfigurationError(f"component {comp!r} has no {direction} {port!r}; its "
                                     f"{direction}s: {', '.join(ports) or '(none)'}")
        return comp, port

    def _parse_connections(self, connections) -> dict:
        pairs = ([(src, dst) for dst, src in connections.items()]
                 if isinstance(connections, Mapping) else list(connections))
        out = {}
        for src, dst in pairs:
            s, d = self._port(src, "output"), self._port(dst, "input")
            if d in out:
                raise ConfigurationError(f"input {dst!r} is connected twice "
                                         f"(from {'.'.join(out[d])} and {src})")
            out[d] = s
        for c in self.components:
            if c.kind != "discrete":
                continue
            for p in c.input_names:
                if (c.name, p) not in out:
                    signals = [f"{o.name}.{q}" for o in self.components for q in o.output_names]
                    raise ConfigurationError(
                        f"input {c.name}.{p} is not connected; available signals: {', '.join(signals)}")
        return out

    def _base_step(self, step_size):
        periods = {c.name: _fraction(c.period) for c in self.components}
        if not periods:
            raise ConfigurationError("no components")
        if step_size is None:
            base = Fraction(0)
            for p in periods.values():
                base = Fraction(math.gcd(base.numerator * p.denominator, p.numerator * base.denominator),
                                base.denominator * p.denominator)
        else:
            base = _fraction(step_size)
            if base <= 0:
                raise ConfigurationError(f"step_size must be > 0, got {step_size}")
        self._ratio = {}
        for name, p in periods.items():
            r = p / base
            if r.denominator != 1:
                raise ConfigurationError(
                    f"component {name!r}: period {float(p)} s is not an integer multiple of the "
                    f"base step {float(base)} s")
            self._ratio[name] = r.numerator
        self._base = base
        return float(base)

    # ---------------------------------------------------------------- layout
    def _layout(self):
        slots, n = {}, 0
        self._out_slices = {}
        for c in self.components:
            self._out_slices[c.name] = slice(n, n + len(c.output_names))
            for p in c.output_names:
                slots[(c.name, p)] = n
                n += 1
        self.signal_names = [f"{c}.{p}" for (c, p) in slots]
        self._n_signals = n

        def spec(c):
            ports = [p for p in c.input_names if (c.name, p) in self.connections]
            if c.kind == "fmu":
                c.use_inputs(ports)          # the FMU sets exactly these inputs each step
            idx = np.array([slots[self.connections[(c.name, p)]] for p in ports], dtype=np.intp)
            if len(idx) and np.all(np.diff(idx) == 1):
                return ports, slice(int(idx[0]), int(idx[-1]) + 1)   # contiguous: a view
            return ports, idx

        self._in_specs = {c.name: spec(c) for c in self.components}
        hyper = 1
        for r in self._ratio.values():
            hyper = hyper * r // math.gcd(hyper, r)
        self._hyper = hyper

    def _schedule(self):
        sched = []
        for j in range(self._hyper):
            due = [c for c in self.components if j % self._ratio[c.name] == 0]
            disc = tuple((c, self._in_specs[c.name][1], self._out_slices[c.name])
                         for c in due if c.kind == "discrete")
            fmus = tuple((c, self._in_specs[c.name][1], self._out_slices[c.name])
                         for c in due if c.kind == "fmu")
            sched.append((disc, fmus))
        return sched

    # ---------------------------------------------------------------- running
    def run(self, stop_time: float, start_time: float = 0.0) -> pd.DataFrame:
        """Run from ``start_time`` to ``stop_time`` [s]; returns every signal, one row per
        base step (index ``time``, columns ``component.port``).

        After the run, ``self.timings`` holds the wall times [s] of ``setup`` (resets,
        FMU instantiation), ``loop`` and ``teardown``.

        Raises
        ------
        CosimError
            A component raised, an FMU returned discard/error/fatal, or a signal became
            NaN or inf; the message names the component and the time, and
            ``error.results`` holds the rows recorded until then. FMU instances are
            always freed.
        """
        h = self._base
        span = _fraction(stop_time) - _fraction(start_time)
        if span <= 0 or (span / h).denominator != 1:
            raise ConfigurationError(f"stop_time - start_time = {float(span)} s must be a positive "
                                     f"multiple of the base step {float(h)} s")
        n = (span / h).numerator
        t0, hf = float(start_time), float(h)
        values = np.zeros(self._n_signals)
        rec = np.full((n + 1, self._n_signals), np.nan)
        sched = self._schedule()
        jacobi = self.order == "jacobi"
        current, k, done = None, 0, 0      # done: rows recorded so far
        clock = time.perf_counter()
        self.timings = {}
        try:
            for c in self.components:
                current = c
                out = self._out_slices[c.name]
                init = np.asarray(c.reset(t0), float)
                if init.shape != (out.stop - out.start,):
                    raise ValueError(f"reset returned shape {init.shape}, expected ({out.stop - out.start},)")
                values[out] = init
                if c.kind == "fmu" and len(c.in_view) != len(self._in_specs[c.name][0]):
                    raise ValueError("FMU input buffer does not match its connections")
            L = self._hyper
            self.timings["setup"] = time.perf_counter() - clock
            clock = time.perf_counter()
            for k in range(n + 1):
                t = t0 + k * hf
                disc, fmus = sched[k % L]
                for f, _, out in fmus:
                    values[out] = f.out_view
                src = values.copy() if jacobi else values
                for c, inp, out in disc:
                    current = c
                    values[out] = c.sample(t, src[inp])
                rec[k] = values
                done = k + 1
                if not done & 63 and not np.isfinite(rec[done - 64: done]).all():
                    self._raise_nonfinite(rec, done, t0, hf)
                if k == n:
                    break
                for f, inp, _ in fmus:
                    current = f
                    f.in_view[:] = src[inp]
                    f.advance(t, f.period)
            self._raise_nonfinite(rec, done, t0, hf)
            self.timings["loop"] = time.perf_counter() - clock
        except CosimError as e:
            if e.results is None:
                e.results = self._frame(rec[:done], t0, hf)
            raise
        except Exception as e:
            # a non-finite signal recorded before the failure is its root cause
            self._raise_nonfinite(rec, done, t0, hf)
            t = t0 + k * hf
            raise CosimError(f"component {current.name!r} failed at t = {t:g} s: {e}",
                             current.name, t, self._frame(rec[:done], t0, hf)) from e
        finally:
            clock = time.perf_counter()
            for c in self.components:
                c.close()
            self.timings["teardown"] = time.perf_counter() - clock
        return self._frame(rec, t0, hf)

    def _raise_nonfinite(self, rec, done, t0, h):
        """Raise CosimError at the first NaN or inf among the ``done`` recorded rows, if any.

        Rows are checked in blocks of 64 during the run (and all at its end); the error
        names the signal, its component and the time, and keeps the rows before it.
        """
        bad = ~np.isfinite(rec[:done])
        if not bad.any():
            return
        k, j = np.argwhere(bad)[0]
        sig, t = self.signal_names[j], t0 + k * h
        raise CosimError(f"signal {sig} is {rec[k, j]} at t = {t:g} s (component "
                         f"{sig.split('.')[0]!r})", sig.split(".")[0], t, self._frame(rec[:k], t0, h))

    def _frame(self, rec, t0, h):
        index = pd.Index(t0 + h * np.arange(len(rec)), name="time")
        return pd.DataFrame(rec, index=index, columns=self.signal_names)

    def sample_counts(self, stop_time: float, start_time: float = 0.0) -> dict[str, int]:
        """How many times each component is sampled/stepped in a run (a planning aid)."""
        n = int(round((stop_time - start_time) / self.step_size))
        return {c.name: (n // self._ratio[c.name] + 1 if c.kind == "discrete"
                         else n // self._ratio[c.name]) for c in self.components}
