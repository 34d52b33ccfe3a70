"""Inertia-wheel pendulum of seed 002 (eqs 1-2), all three states measured (``C = I``), coupling sign
-1 where the paper prints +1, defaults of the 1-D Cubli; the reasons: the user guide's page "Plant models
and their equations"."""
from __future__ import annotations

import math

import casadi as ca

from .catalog import register_model
from .plant import PlantModel
from .variables import Variable

__all__ = ["build", "dynamics", "measurement"]

STATES = (
    Variable("alpha", "rad", "pendulum angle from upright vertical", 0.0),
    Variable("alpha_dot", "rad/s", "pendulum angular rate", 0.0),
    Variable("phi_dot", "rad/s", "wheel speed relative to the body", 0.0),
)
INPUTS = (Variable("i", "A", "motor current", 0.0),)
OUTPUTS = tuple(v.measured(f"measured {what} (C = I)")
                for v, what in zip(STATES, ("pendulum angle", "pendulum rate", "wheel speed"), strict=True))
PARAMETERS = (
    Variable("Iw", "kg.m2", "wheel inertia about its axis (I_k)", 0.57e-3, "positive"),
    Variable("Ib", "kg.m2", "body inertia about the pivot", 3.34e-3, "positive"),
    Variable("mb", "kg", "body mass", 0.419, "positive"),
    Variable("lb", "m", "pivot to body centre of mass", 0.075, "nonnegative"),
    Variable("mw", "kg", "wheel mass", 0.204, "positive"),
    Variable("lw", "m", "pivot to wheel axis", 0.085, "nonnegative"),
    Variable("Cb", "N.m.s/rad", "body (pivot) viscous friction, b_alpha", 1.02e-3, "nonnegative"),
    Variable("Cw", "N.m.s/rad", "wheel bearing viscous friction, b_phi", 0.05e-3, "nonnegative"),
    Variable("Km", "N.m/A", "motor torque constant, k", 25.1e-3, "positive"),
    Variable("g", "m/s2", "gravitational acceleration", 9.81, "positive"),
    Variable("s", "1", "coupling sign of the wheel reaction torque (physical: -1; the paper prints +1)",
             -1.0, "sign"),
)


def dynamics(x, u, p):
    """Seed 002 eqs 1-2, ``phi'' = (k i - b_phi phi') / I_k`` and
    ``alpha'' = (s I_k phi'' + m_c g l_p sin(alpha) - b_alpha alpha') / (I_r + I_k)``,
    with the Cubli parameters mapped as below (``b_alpha = Cb``, ``b_phi = Cw``, ``k = Km``), of the state
    ``x`` (alpha, alpha_dot, phi_dot) and input ``u`` (motor current i), SX columns; ``p`` the parameter symbols.
    """
    alpha, alpha_dot, phi_dot, i = x[0], x[1], x[2], u[0]
    I_k = p["Iw"]
    I_r = p["Ib"] + p["mw"] * p["lw"] ** 2
    m_c = p["mb"] + p["mw"]
    l_p = (p["mb"] * p["lb"] + p["mw"] * p["lw"]) / m_c
    phi_dd = (p["Km"] * i - p["Cw"] * phi_dot) / I_k                                  # eq 1
    alpha_dd = (p["s"] * I_k * phi_dd + m_c * p["g"] * l_p * ca.sin(alpha)
                - p["Cb"] * alpha_dot) / (I_r + I_k)                                  # eq 2
    return ca.vertcat(alpha_dot, alpha_dd, phi_dd)


def measurement(x, p):
    """C = I: all three states of ``x`` (SX column) are measured (seed 002); ``p``, the parameter symbols, unused."""
    return ca.vertcat(x[0], x[1], x[2])


@register_model("iwp")
def build() -> PlantModel:
    """The model with its default parameters (registered as ``"iwp"``)."""
    return PlantModel("iwp", "InertiaWheelPendulum",
                      "Inertia-wheel pendulum (seed 002 eqs 1-2, coupling sign -1)",
                      STATES, INPUTS, OUTPUTS, PARAMETERS, dynamics, measurement,
                      example_x0=[0.05, 0.0, 0.0], example_input=lambda t: [0.05 * math.sin(2 * math.pi * t)])
