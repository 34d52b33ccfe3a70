"""Experiment settings (frozen dataclasses) from the command line (``--set name=value``) and
TOML files (``--settings FILE``), and back into the output's ``settings.toml``
(docs/guide/experiments.md)."""
from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Iterable

from fmu_models.errors import ConfigurationError, PendulumCosimError, UnknownNameError
from fmu_models.infra.checks import finite, positive, positive_int
from fmu_models.infra.memory import check_fits

from .. import tomlfile

__all__ = ["RECORD_BYTES_PER_STEP", "CommonSettings", "apply_overrides", "check_common", "check_consistency",
           "from_mapping", "load_settings", "to_toml"]


#: Bytes an experiment keeps per realisation and step (truth, measurements, each filter's
#: estimate and variances), the basis of the cap on ``runs x steps``.
RECORD_BYTES_PER_STEP = 512


def check_consistency(settings, priors) -> None:
    """Checks of the consistency and bound settings a campaign shares: ``pcrb_prior`` one of
    ``priors``, ``confidence`` strictly between 0 and 1, ``whiteness_lags`` an integer >= 1
    shorter than the run's ``steps``."""
    if settings.pcrb_prior not in priors:
        raise UnknownNameError(f"pcrb_prior must be one of {list(priors)}, got {settings.pcrb_prior!r}")
    if not 0.0 < finite(settings.confidence, "confidence") < 1.0:
        raise ConfigurationError(f"confidence must lie strictly between 0 and 1, got {settings.confidence!r}")
    positive_int(settings.whiteness_lags, "whiteness_lags")
    if settings.whiteness_lags >= settings.steps:
        raise ConfigurationError(f"whiteness_lags = {settings.whiteness_lags} must be shorter than the "
                                 f"{settings.steps} steps")


def check_common(settings) -> None:
    """Checks every experiment's settings share: ``runs`` an integer >= 1, ``seed`` an
    integer >= 0, ``duration`` and ``T`` positive with at least one step, the records of
    ``runs x steps`` within memory (:data:`RECORD_BYTES_PER_STEP` each), and every other
    number finite."""
    positive_int(settings.runs, "runs")
    positive_int(settings.seed, "seed", minimum=0)
    positive(settings.duration, "duration")
    positive(settings.T, "T")
    steps = round(settings.duration / settings.T)
    if steps < 1:
        raise ConfigurationError("duration must be at least one period T")
    check_fits(RECORD_BYTES_PER_STEP * settings.runs * (steps + 1),
               f"the records of {settings.runs} realisations x {steps} steps (duration {settings.duration:g} s / "
               f"T {settings.T:g} s)", "fewer runs or a shorter duration")
    for f in dataclasses.fields(settings):
        v = getattr(settings, f.name)
        if isinstance(v, float) and not math.isfinite(v):
            raise ConfigurationError(f"setting {f.name} must be finite, got {v}")


class CommonSettings:
    """The base of the experiments' settings dataclasses (fields ``runs``, ``seed``,
    ``duration`` [s] and ``T`` [s]): :func:`check_common` after construction, and ``steps``."""

    def __post_init__(self):
        check_common(self)

    @property
    def steps(self) -> int:
        """Steps of a realisation, ``duration / T``."""
        return round(self.duration / self.T)


def _parse(text: str):
    """A value from its command-line text: TOML syntax (``1e-3``, ``[1, 2]``, ``"eqs"``,
    ``true``), else the bare text as a string."""
    try:
        return tomlfile.loads(f"v = {text}", "--set value")["v"]
    except ConfigurationError as e:
        if "nested" in str(e) or "MiB" in str(e):
            raise
        return text


def _convert(name: str, value, kind, default):
    """``value`` as the type of the field ``name`` (its annotation, else its default's)."""
    origin = typing.get_origin(kind)
    if origin in (typing.Union, types.UnionType):
        if value is None or (isinstance(value, str) and value.lower() == "none"):
            return None
        kind = next(a for a in typing.get_args(kind) if a is not type(None))
    if kind is tuple or origin is tuple or isinstance(default, tuple):
        if not isinstance(value, (list, tuple)):
            value = [value]
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    if kind is bool and not isinstance(value, bool):
        raise ConfigurationError(f"setting {name} must be true or false, got {value!r}")
    if kind in (int, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigurationError(f"setting {name} must be a number, got {value!r}")
        if kind is int and float(value) != int(value):
            raise ConfigurationError(f"setting {name} must be an integer, got {value!r}")
        return kind(value)
    return str(value) if kind is str else value


def from_mapping(settings, values: dict):
    """A copy of the dataclass ``settings`` with the fields in ``values`` replaced
    (converted to each field's type); unknown names are refused, listing the valid ones."""
    hints = typing.get_type_hints(type(settings))
    types_ = {f.name: hints.get(f.name, type(f.default)) for f in dataclasses.fields(settings)}
    unknown = sorted(set(values) - set(types_))
    if unknown:
        raise UnknownNameError(f"unknown setting(s) {', '.join(unknown)}; valid: {', '.join(types_)}")
    new = {k: _convert(k, v, types_[k], getattr(settings, k)) for k, v in values.items()}
    try:
        return dataclasses.replace(settings, **new)
    except PendulumCosimError:
        raise
    except (TypeError, ValueError, IndexError, KeyError, AttributeError) as e:
        # a value of the right outer type but the wrong shape inside (scenarios = [1]),
        # caught by the experiment's own checks as a built-in error
        given = "; ".join(f"{k} = {_toml_value(v)} (default {_toml_value(getattr(settings, k))})"
                          for k, v in new.items())
        raise ConfigurationError(f"setting(s) {given}: not of the form the experiment needs ({e})") from None


def apply_overrides(settings, overrides: Iterable[str]):
    """``settings`` with ``name=value`` overrides (command-line ``--set``) applied."""
    values = {}
    for item in overrides:
        if "=" not in item:
            raise ConfigurationError(f"--set needs name=value, got {item!r}")
        name, text = (part.strip() for part in item.split("=", 1))
        try:
            values[name] = _parse(text)
        except ConfigurationError as e:          # too deep or too long: say which setting
            raise ConfigurationError(f"--set {name}=...: {e}") from None
    return from_mapping(settings, values)


def load_settings(settings, path):
    """``settings`` with the values of the TOML file ``path`` (a flat table of fields)."""
    data = tomlfile.read(path, "settings file")
    data.pop("experiment", None)
    return from_mapping(settings, data)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"none"' if v is None else repr(v)


def to_toml(settings, experiment: str) -> str:
    """The dataclass ``settings`` of ``experiment`` (its name) as a TOML file that
    :func:`load_settings` reads back."""
    lines = [f'experiment = "{experiment}"']
    lines += [f"{f.name} = {_toml_value(getattr(settings, f.name))}" for f in dataclasses.fields(settings)]
    return "\n".join(lines) + "\n"
