"""The estimator component: any filter of :mod:`estimators` as a co-simulation component."""
from __future__ import annotations

import ctypes
from collections.abc import Callable
from pathlib import Path

import numpy as np

from estimators.adaptive import AdaptationRecord
from estimators.base import KalmanBase
from estimators.filter_fmu import export_filter_fmu, filter_parameters
from fmu_models.errors import ConfigurationError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import positive

from ..core.component import BoundCalls, Component, ExportedFMU
from ..core.native import OP_FILTER, OP_HOLD, OP_HOOK, OP_RECORD, OP_SUMMARY, Op

COVARIANCE_OUTPUTS = ("diagonal", "full")


class EstimatorComponent(BoundCalls, Component, kind="estimator"):
    """Runs a filter of :mod:`estimators` at its model's sample period.

    Input ports: the model's inputs and outputs (the measurements). Output ports: the state
    estimate (state names), the covariance diagonal (``P_<state>``), with
    ``covariance="full"`` also its upper off-diagonal entries ``P_<i>_<j>`` (0-based, ``i <
    j``), and ``nis``.

    Timing (seed 000 eqs 14-23): the initial estimate at the first instant, then at each
    ``t_k`` one ``step(u_{k-1}, y_k)`` (the input read at the previous instant, the measurement
    at ``t_k``): a direct dependence on the measurements only, wherever the component sits.

    Parameters
    ----------
    name : str
    make_filter : callable
        Returns a new filter (at every reset), e.g. ``lambda: EKF(system, x0, P0, Q, R)``.
    period : float, optional
        Must equal the filter's model period ``system.dt`` (default: that period).
    covariance : {"diagonal", "full"}
        Which covariance entries to output (default the diagonal).
    """

    def __init__(self, name: str, make_filter: Callable[[], KalmanBase], period: float | None = None,
                 covariance: str = "diagonal"):
        if not callable(make_filter):
            raise TypeMismatchError(f"{name}: make_filter must be a callable returning a filter")
        probe = make_filter()
        if not isinstance(probe, KalmanBase):
            raise TypeMismatchError(f"{name}: make_filter returned {type(probe).__name__}, not a filter")
        if covariance not in COVARIANCE_OUTPUTS:
            raise UnknownNameError(f"{name}: covariance must be one of {COVARIANCE_OUTPUTS}, got {covariance!r}")
        sys_ = probe.system
        period = sys_.dt if period is None else period
        if abs(period - sys_.dt) > 1e-12 * max(1.0, sys_.dt):
            raise ConfigurationError(f"{name}: period {period} s differs from the filter model's dt "
                                     f"{sys_.dt} s; discretise the model with dt = period")
        n = sys_.nx
        self.covariance = covariance
        off = [f"P_{i}_{j}" for i, j in zip(*self._upper(n))]
        outputs = sys_.state_names + [f"P_{s}" for s in sys_.state_names] + off + ["nis"]
        super().__init__(name, period, inputs=sys_.input_names + sys_.output_names, outputs=outputs,
                         feedthrough={o: sys_.output_names for o in outputs})
        self.make_filter, self.filter = make_filter, probe
        self._nu, self._nx = sys_.nu, n
        self.connected_inputs = self.input_names
        self.estimated_states = list(sys_.state_names)

    def _upper(self, n: int) -> tuple:
        """The indices of the off-diagonal covariance entries output (none unless "full")."""
        return np.triu_indices(n, 1) if self.covariance == "full" else (np.zeros(0, int),) * 2

    @classmethod
    def from_scenario(cls, name, table, context):
        """The keys ``filter`` (:data:`estimators.FILTERS`), ``model`` (a registered model, with
        ``model_parameters``, ``method``, ``substeps``; or a Model Exchange FMU's path, with the
        keys of :meth:`~cosim.scenario.ScenarioContext.fmu_process_model`), ``period``,
        ``bias_on`` (augment the state with the offset of this output), ``covariance``; the
        other keys are the filter's constructor's."""
        import estimators

        t = dict(table)
        for key in ("filter", "model", "period"):
            if key not in t:
                raise ConfigurationError(f"component {name!r} (estimator) needs the key {key!r}")
        filt = estimators.FILTERS.get(t.pop("filter"))
        period = positive(t.pop("period"), f"component {name!r}: period [s]")
        model = t.pop("model")
        if isinstance(model, str) and model.lower().endswith(".fmu"):
            system = context.fmu_process_model(model, period, t, f"component {name!r} (estimator)")
        else:
            model = context.model(model, t.pop("model_parameters", None))
            system = estimators.discretize(model, period, t.pop("method", "euler"), t.pop("substeps", 1))
        bias = t.pop("bias_on", None)
        if bias is not None:
            system = estimators.augment_rate_bias(system, bias)
        covariance = t.pop("covariance", "diagonal")
        kwargs = context.check_keys(filt, t, f"component {name!r} (estimator, filter {filt.__name__})",
                                    skip=("system",))
        return cls(name, lambda: filt(system, **kwargs), period, covariance=covariance)

    def timing(self) -> str:
        return "outputs at t: the estimate after predict(u read at the previous instant) and update(y at t)"

    def bind(self, values, inputs, outputs, integers=None):
        """The master's fast path (:class:`~cosim.core.component.FastBinding`): the filter's
        step reads ``values`` and writes its summary straight into ``values[outputs]``."""
        f, nu = self.filter, self._nu
        summary = None              # bound at the first call from Python (the native kernel writes its own)
        if isinstance(inputs, slice):
            u_at, y_at = slice(inputs.start, inputs.start + nu), slice(inputs.start + nu, inputs.stop)
        else:
            u_at, y_at = inputs[:nu], inputs[nu:]
        u_prev = np.zeros(nu)
        cur = np.zeros(4, dtype=np.int64)   # the native kernel's [state copy, step count, started, stepped]
        step = f.step

        def output_fn(t: float) -> None:
            nonlocal summary
            if cur[2]:
                step(u_prev, values[y_at])
            if summary is None:
                summary = f.bind_summary(values[outputs], self.covariance)
            summary()

        def update_fn(t: float) -> None:
            u_prev[:] = values[u_at]
            cur[2] = 1

        ops = self._native_ops(values, u_at, y_at, outputs, u_prev, cur)
        if ops is not None:
            output_fn.native, update_fn.native = ops
        return output_fn, update_fn

    def native_reason(self) -> str | None:
        """Why this filter's calls run in Python (None: its compiled step runs in the native kernel)."""
        f = self.filter
        if f.backend != "compiled" or getattr(f, "_step_library", None) is None:
            return "the filter runs in CasADi's virtual machine (no compiled step)"
        if type(f).step is not KalmanBase.step:
            return f"{type(f).__name__} runs Python code in its step"
        return None

    def _compiled_step(self):
        """The filter's compiled step as the kernel calls it, ``(library, symbol, iw, w, argument
        and result pointers per bound step)``, kept per filter; None if the library cannot be read."""
        f = self.filter
        cached = getattr(self, "_compiled", None)
        if cached is None or cached[0] is not f:
            bound = f._rt._steps
            fn = bound[0].fn
            try:
                lib = ctypes.CDLL(str(f._step_library))
                sym = ctypes.cast(getattr(lib, fn.name()), ctypes.c_void_p).value
            except (OSError, AttributeError):
                return None
            iw, w = np.zeros(max(fn.sz_iw(), 1), dtype=np.int64), np.zeros(max(fn.sz_w(), 1))
            ptrs = [((ctypes.c_void_p * max(fn.sz_arg(), 1))(*[a.ctypes.data for a in b.args]),
                     (ctypes.c_void_p * max(fn.sz_res(), 1))(*[r.ctypes.data for r in b.res])) for b in bound]
            self._compiled = cached = (f, lib, sym, iw, w, ptrs)
        return cached[1:]

    def _native_ops(self, values, u_at, y_at, outputs: slice, u_prev, cur):
        """The kernel's operations (output: the compiled step :meth:`step` evaluates, on the same
        arrays, the adaptive filters' hook, the summary; update: keep the inputs), or None."""
        if self.native_reason() is not None or (compiled := self._compiled_step()) is None:
            return None
        f, (lib, sym, iw, w, ptrs) = self.filter, compiled
        rt, n = f._rt, self._nx
        upi, upj = (np.ascontiguousarray(a, np.int64) for a in self._upper(n))
        idx = np.arange(len(values))
        uidx, yidx = (np.ascontiguousarray(idx[at], np.int64) for at in (u_at, y_at))
        xs, Ps = rt.pairs["x"], rt.pairs["P"]
        cell, count = rt.cell, f._count

        def sync_in() -> None:
            cur[0], cur[1] = cell[0], count[0]

        def sync_out() -> None:
            cell[0], count[0] = int(cur[0]), int(cur[1])

        def fail(op, t: float) -> None:
            f._explain("step")

        fields = dict(fn=sym, arg=tuple(ctypes.addressof(a) for a, _ in ptrs),
                      res=tuple(ctypes.addressof(r) for _, r in ptrs), iw=iw.ctypes.data, w=w.ctypes.data,
                      ub=f._u.ctypes.data, yb=f._y.ctypes.data, uprev=u_prev.ctypes.data, yidx=yidx.ctypes.data,
                      ny=len(yidx), nu=len(uidx), nx=n, nup=len(upi), cur=cur.ctypes.data,
                      status_out=rt.status.ctypes.data, x=(xs[0].ctypes.data, xs[1].ctypes.data),
                      P=(Ps[0].ctypes.data, Ps[1].ctypes.data), nis=rt.outputs["nis"].ctypes.data,
                      out=values[outputs].ctypes.data, uidx=uidx.ctypes.data, upi=upi.ctypes.data,
                      upj=upj.ctypes.data)
        keep = (lib, iw, w, ptrs, upi, upj, uidx, yidx, u_prev, cur, rt._steps)
        ops = [Op(OP_FILTER, fields, keep, fail, sync_in, sync_out)]
        if getattr(f, "_after", False):           # the filter's after_step, from Python
            ops.append(self._after_op(cur, len(yidx), sync_in, sync_out))
        ops.append(Op(OP_SUMMARY, dict(fields), keep))
        return ops, [Op(OP_HOLD, dict(fields), keep)]

    def _after_op(self, cur, ny: int, sync_in, sync_out) -> Op:
        """The kernel's operation after an adaptive filter's step (its ``after_step``, or its records)."""
        f = self.filter
        flag = f._out("adapted") if type(f).after_step is AdaptationRecord.after_step else None
        after = f.after_step

        def hook() -> None:
            sync_out()
            after()
            sync_in()
        records = getattr(f, "records_only", None)
        if flag is None or not callable(records) or not records() or "Q" not in f._rt.pairs or "R" not in f._rt.pairs:
            return Op(OP_HOOK, dict(cur=cur.ctypes.data, buf=0 if flag is None else flag.ctypes.data), (cur, flag),
                      hook=hook)
        history, Qs, Rs = f.history, f._rt.pairs["Q"], f._rt.pairs["R"]

        def rebind(op) -> None:
            op.out, op.n = history.rows.ctypes.data, len(history.rows)

        return Op(OP_RECORD, dict(cur=cur.ctypes.data, buf=flag.ctypes.data, out=history.rows.ctypes.data,
                                  n=len(history.rows), iw=history.count.ctypes.data, nx=self._nx, ny=ny,
                                  x=(Qs[0].ctypes.data, Qs[1].ctypes.data), P=(Rs[0].ctypes.data, Rs[1].ctypes.data)),
                  (cur, flag, history, Qs, Rs), hook=hook, rebind=rebind)

    def reset(self, t0):
        super().reset(t0)
        if self.filter.k:
            self.filter = self.make_filter()
        self._private = None

    def export_fmu(self, folder: Path, fmi_version: int = 2, clocked: bool = False) -> ExportedFMU:
        """The filter as an estimator FMU (:func:`estimators.filter_fmu.export_filter_fmu`;
        ``clocked``: its clocked form, FMI 3.0) with this component's timing and outputs (but the
        off-diagonal ``P_<i>_<j>``)."""
        filt = self.make_filter()
        path = export_filter_fmu(filt, folder, fmi_version, name=self._fmu_identifier(),
                                 file_name=f"{self.name}.fmu", clocked=clocked)
        return ExportedFMU(path, filter_parameters(filt))
