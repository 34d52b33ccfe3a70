"""Cart-inverted pendulum of seed 000 (eqs 8-11, Table 1) with the papers' errata fixed (``M3`` uses
``mp``, ``Bc`` in N s/m; the errata and their checks: the user guide's page "Plant models and their equations")."""
from __future__ import annotations

import casadi as ca

from .catalog import register_model
from .plant import PlantModel
from .variables import Variable

__all__ = ["build", "dynamics", "measurement"]

STATES = (
    Variable("x", "m", "cart position (seed 000 x1)", 0.5),
    Variable("x_dot", "m/s", "cart velocity (x2)", 0.0),
    Variable("theta", "rad", "pole angle from upright, positive towards +x (x3)", 1.8),
    Variable("theta_dot", "rad/s", "pole angular rate (x4)", 0.5),
)
INPUTS = (Variable("F", "N", "horizontal force on the cart", 0.0),)
OUTPUTS = (STATES[0].measured("measured cart position (noise-free h(x), eq 23)"),
           STATES[2].measured("measured pole angle (noise-free h(x), eq 23)"))
PARAMETERS = (
    Variable("mc", "kg", "cart mass (Table 1)", 0.94, "positive"),
    Variable("mp", "kg", "pole mass (Table 1)", 0.23, "positive"),
    Variable("l", "m", "pivot to pole centre of mass; pole inertia I = mp l^2/3 (Table 1)",
             0.33, "positive"),
    Variable("Bc", "N.s/m", "cart viscous friction (Table 1; unit corrected)", 0.44, "nonnegative"),
    Variable("Bp", "N.m.s/rad", "pivot viscous friction (Table 1)", 0.05, "nonnegative"),
    Variable("g", "m/s2", "gravitational acceleration", 9.81, "positive"),
)


def dynamics(x, u, p):
    """Seed 000 eqs 8-11 with ``M3 = M1 M2 - mp^2 l^2 cos^2 x3`` (Table 1 erratum fixed) of the state ``x``
    (x, x_dot, theta, theta_dot) and the input ``u`` (force F), SX columns, and ``p`` the parameter symbols by name.
    """
    mc, mp, l, Bc, Bp, g = (p[k] for k in ("mc", "mp", "l", "Bc", "Bp", "g"))
    x2, x3, x4, F = x[1], x[2], x[3], u[0]
    s, c = ca.sin(x3), ca.cos(x3)
    inertia = mp * l**2 / 3
    M1 = mc + mp
    M2 = inertia + mp * l**2
    M3 = M1 * M2 - mp**2 * l**2 * c**2
    x2dot = (-Bc * M2 * x2 + mp * l * Bp * x4 * c - mp**2 * l**2 * g * s * c
             + mp * l * M2 * x4**2 * s + M2 * F) / M3                      # eq 9
    x4dot = (-Bp * M1 * x4 + mp * l * Bc * x2 * c - mp**2 * l**2 * x4**2 * s * c
             + mp * l * g * M1 * s - mp * l * c * F) / M3                  # eq 11
    return ca.vertcat(x2, x2dot, x4, x4dot)                                # eqs 8, 10


def measurement(x, p):
    """Eq 23: cart position and pole angle (``y_k = [x1_k, x3_k]``; eqs 18-19 print ``x_{k-1}``, an index
    slip) of the state ``x`` (SX column); ``p``, the parameter symbols, unused."""
    return ca.vertcat(x[0], x[2])


@register_model("cartpole")
def build() -> PlantModel:
    """The model with its default parameters (registered as ``"cartpole"``)."""
    return PlantModel("cartpole", "CartPole",
                      "Cart-inverted pendulum (seed 000 eqs 8-11, Table 1 corrected)",
                      STATES, INPUTS, OUTPUTS, PARAMETERS, dynamics, measurement,
                      example_input=lambda t: [-0.5 if t < 2.0 else 0.5])       # seed 000 Figure 2
