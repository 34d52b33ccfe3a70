"""Fold a compiled step Function over whole trajectories in native code, without copies.

CasADi's ``mapaccum`` copies the state and every output through work vectors at each step
(0.30 us a step on top of the 0.18 us of the cart-pole EKF step); :class:`NativeFold`'s driver,
compiled with the step, calls it in a loop with pointers into the caller's numpy arrays (strides
per step and per realisation; a state whose history nobody reads cycles through two rows).
The VM backend folds through ``mapaccum``.
"""
from __future__ import annotations

import ctypes
from functools import partial

import casadi as ca
import numpy as np

from fmu_models.infra.memory import check_fits

from ._compiled import compile_functions
from .protocol import renamed

__all__ = ["FOLD_NAME", "NativeFold", "compile_with_fold"]

_DRIVER = r"""
#include <stdlib.h>
/* Generated into the same library as the step: fold it over n_steps for each of runs. */
int %(name)s_fold(long runs, long n_steps,
                  const double *const *arg0, const long *arg_stride, const long *arg_run_stride,
                  double *const *res0, const long *res_stride, const long *res_run_stride,
                  const long *acc_out, const long *res_cycle) {
    casadi_int sz_arg, sz_res, sz_iw, sz_w;
    const casadi_real **arg;
    casadi_real **res, *w;
    casadi_int *iw;
    long r, k, i, j;
    int n_in = %(n_in)d, n_out = %(n_out)d, flag = 0;
    %(name)s_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    arg = (const casadi_real **)malloc(sizeof(casadi_real *) * (sz_arg > n_in ? sz_arg : n_in));
    res = (casadi_real **)malloc(sizeof(casadi_real *) * (sz_res > n_out ? sz_res : n_out));
    iw = (casadi_int *)malloc(sizeof(casadi_int) * (sz_iw + 1));
    w = (casadi_real *)malloc(sizeof(casadi_real) * (sz_w + 1));
    if (!arg || !res || !iw || !w) { flag = -1; goto done; }
    for (r = 0; r < runs; r++) {
        for (k = 0; k < n_steps; k++) {
            for (i = 0; i < n_in; i++) {
                j = acc_out[i];       /* the output carrying a state input; step 0 reads arg0 */
                if (j >= 0 && k > 0)
                    arg[i] = res0[j] + r * res_run_stride[j]
                             + (res_cycle[j] ? (k - 1) %% 2 : k - 1) * res_stride[j];
                else
                    arg[i] = arg0[i] + r * arg_run_stride[i] + k * arg_stride[i];
            }
            for (i = 0; i < n_out; i++)
                res[i] = res0[i] + r * res_run_stride[i] + (res_cycle[i] ? k %% 2 : k) * res_stride[i];
            if (%(name)s(arg, res, iw, w, 0)) { flag = 1 + (int)k; goto done; }
        }
    }
done:
    free(arg); free(res); free(iw); free(w);
    return flag;
}
"""


#: The name of a fused step compiled with its fold driver (:func:`compile_with_fold`).
FOLD_NAME = "foldstep"


def compile_with_fold(step: ca.Function, backend: str = "compiled") -> tuple:
    """``step`` compiled together with its fold driver into one library: ``(the step as
    an external Function, backend used, library path or None)``. One compilation serves
    both a filter's single steps and its folds (:class:`NativeFold` with ``library=``)."""
    code = _DRIVER % {"name": FOLD_NAME, "n_in": step.n_in(), "n_out": step.n_out()}
    (fn,), used, lib = compile_functions([renamed(step, FOLD_NAME)], backend, extra_code=code, return_library=True)
    return (fn if used == "compiled" else step), used, lib


class NativeFold:
    """A step Function folded over trajectories (see the module documentation).

    Parameters
    ----------
    step : casadi.Function
        The fused step; its first ``n_state`` inputs are the state, carried by the outputs
        named ``<input>_new``.
    n_state : int
        Number of state inputs.
    backend : {"compiled", "vm"}
    library : path, optional
        The library ``step`` was compiled into with its driver (:func:`compile_with_fold`);
        default: compile it now.
    """

    def __init__(self, step: ca.Function, n_state: int, backend: str = "compiled", library=None):
        self.step, self.n_state = step, n_state
        self.names_in, self.names_out = step.name_in(), step.name_out()
        self._mapped: dict = {}
        self.backend = backend
        if library is None:
            _, self.backend, library = compile_with_fold(step, backend)
        if self.backend == "compiled":
            self._fold = getattr(ctypes.CDLL(str(library)), f"{FOLD_NAME}_fold")
            self._fold.restype = ctypes.c_int

    def __call__(self, runs: int, n_steps: int, args: dict, init: dict, outs: dict, cycled=()) -> int:
        """Fold ``n_steps`` steps for each of ``runs`` realisations; arrays by name, float64 with a
        contiguous last axis: the non-state inputs ``args`` ``(runs, n_steps, nnz)`` (per step) or
        ``(runs, nnz)`` (every step), the initial state ``init`` ``(runs, nnz)``, the outputs ``outs``
        ``(runs, n_steps, nnz)`` filled in place (views allowed), the ``cycled`` ones ``(runs, 2,
        nnz)`` (:meth:`outputs`). Returns 0, or ``1 + k`` if the step failed to evaluate at step ``k``."""
        if self.backend != "compiled":
            return self._vm(runs, n_steps, args, init, outs, cycled)
        return self.bind(runs, n_steps, args, init, outs, cycled)()

    def bind(self, runs: int, n_steps: int, args: dict, init: dict, outs: dict, cycled=()):
        """The fold of :meth:`__call__` with its arguments prebuilt once, as a callable without
        arguments (the arrays stay bound and alive, changed in place between calls); compiled
        backend only."""
        P = ctypes.POINTER(ctypes.c_double)
        keep = []

        def ptr(a):
            if a.dtype != np.float64 or (a.shape[-1] > 1 and a.strides[-1] != 8):
                raise ValueError("fold arrays must be float64 with a contiguous last axis")
            keep.append(a)
            return a.ctypes.data_as(P)

        def longs(values) -> ctypes.Array:
            return (ctypes.c_long * len(values))(*values)

        ins = [init[n] if i < self.n_state else args[n] for i, n in enumerate(self.names_in)]
        res = [outs[n] for n in self.names_out]
        call = (ctypes.c_long(runs), ctypes.c_long(n_steps), (P * len(ins))(*[ptr(a) for a in ins]),
                longs([a.strides[1] // 8 if a.ndim == 3 else 0 for a in ins]), longs([a.strides[0] // 8 for a in ins]),
                (P * len(res))(*[ptr(o) for o in res]), longs([o.strides[1] // 8 for o in res]),
                longs([o.strides[0] // 8 for o in res]),
                longs([self.names_out.index(f"{n}_new") if i < self.n_state else -1
                       for i, n in enumerate(self.names_in)]),
                longs([int(n in cycled) for n in self.names_out]))
        run = partial(self._fold, *call)
        run.keep = keep          # the arrays must live as long as the call
        return run

    def outputs(self, runs: int, n_steps: int, init: dict, drop=(), cycle=()) -> tuple[dict, dict]:
        """Arrays for the outputs of a fold: ``(stored, views)``. ``stored[name]`` is
        ``(runs, n_steps, nnz)``, or ``(runs, n_steps + 1, nnz)`` for a state output
        (``<input>_new``) whose row 0 holds ``init[<input>]`` ``(runs, nnz)``; ``views`` are
        what the fold writes (without that row). An output in ``drop`` is not stored (its view
        is one scratch row); a state output in ``cycle`` gets two rows, the last state in row
        ``(n_steps - 1) % 2``."""
        rows = {name: (2 if name in cycle else 0 if name in drop else n_steps + name.endswith("_new"))
                for name in self.names_out}
        total = 8 * runs * sum(rows[n] * self.step.nnz_out(i) for i, n in enumerate(self.names_out))
        check_fits(total, f"the outputs of {runs} x {n_steps} steps of {self.step.name()} "
                   f"({8 * self.step.nnz_out()} bytes a step)",
                   "run shorter records (in pieces), fewer realisations, or keep='estimates'")
        stored, views = {}, {}
        for i, name in enumerate(self.names_out):
            nnz = self.step.nnz_out(i)
            if name in drop:
                views[name] = np.lib.stride_tricks.as_strided(np.empty((1, 1, nnz)), (runs, n_steps, nnz),
                                                              (0, 0, 8))
                continue
            stored[name] = views[name] = np.empty((runs, rows[name], nnz))
            if name.endswith("_new") and name not in cycle:
                stored[name][:, 0] = init[name[:-4]]
                views[name] = stored[name][:, 1:]
        return stored, views

    def _vm(self, runs, n_steps, args, init, outs, cycled=()) -> int:
        """The same fold through ``mapaccum`` in CasADi's virtual machine, of the step on flat arrays."""
        if n_steps not in self._mapped:
            flat = [ca.MX.sym(name, self.step.nnz_in(i)) for i, name in enumerate(self.names_in)]
            res = self.step.call([ca.reshape(a, self.step.size_in(i)) for i, a in enumerate(flat)])
            state = list(range(self.n_state))
            self._mapped[n_steps] = ca.Function("flat", flat, [ca.vec(r) for r in res]).mapaccum("fold", n_steps,
                                                                                                 state, state)
        for r in range(runs):         # a step's inputs and outputs are the columns
            res = self._mapped[n_steps].call([init[name][r] if i < self.n_state else
                                              np.broadcast_to(args[name][r], (n_steps, args[name].shape[-1])).T
                                              for i, name in enumerate(self.names_in)])
            for name, value in zip(self.names_out, res):
                rows = np.asarray(value).T
                if name in cycled:                  # the last two steps, in rows k % 2
                    last = np.arange(max(0, n_steps - 2), n_steps)
                    outs[name][r][last % 2] = rows[last]
                else:
                    outs[name][r] = rows
        return 0
