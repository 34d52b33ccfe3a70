"""Command line: ``pendulum-cosim``."""
from __future__ import annotations

import argparse
import sys

import numpy as np


def _demo(args) -> int:
    """Simulate both models (Euler truth map and RK4) and print trajectories and Jacobians."""
    from fmu_models import get_model

    np.set_printoptions(precision=5, suppress=True, linewidth=110)
    runs = {"cartpole": (lambda t: [-0.5 if t < 2.0 else 0.5]),
            "iwp": (lambda t: [0.05 * np.sin(2 * np.pi * t)])}
    for name, u in runs.items():
        m = get_model(name)
        x0 = m.x0 if name == "cartpole" else np.array([0.05, 0.0, 0.0])
        dt, n = 0.01, int(round(args.duration / 0.01))
        print(f"== {m.description}")
        print(f"   states {m.state_names}, input {m.input_names}, params {m.params}")
        xs = m.simulate(x0, u, dt, n, method="euler")
        xr = m.simulate(x0, u, dt, n, method="rk4", substeps=4)
        print(f"   t [s] | Euler (T = {dt} s) state | RK4 (4 substeps) state")
        for k in range(0, n + 1, max(1, n // 10)):
            print(f"   {k * dt:5.2f} | {xs[k]} | {xr[k]}")
        A, B = m.linearize(np.zeros(m.nx), np.zeros(m.nu))
        F, G = m.jacobians(xs[-1], u(n * dt), dt)
        print("   exact A = df/dx at the upright equilibrium:\n", A)
        print("   exact B = df/du:", B.ravel())
        print(f"   Euler-map Jacobian F at t = {n * dt:.2f} s:\n", F)
        print()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="pendulum-cosim",
        description="FMI co-simulation of two benchmark pendulums for nonlinear state estimation.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="simulate both plant models and print trajectories and Jacobians")
    demo.add_argument("--duration", type=float, default=5.0, help="simulated time [s] (default 5)")
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
