"""Every FMU the project writes goes through this package (the estimator FMUs of
:mod:`estimators.filter_fmu` too): one packer, one model-description writer, one variable
list and one ``model_config.h`` schema for the three C cores in ``c/``.

>>> from fmu_models.export import build_fmu
>>> path = build_fmu("cartpole", "fmus")            # doctest: +SKIP
"""
from .pack import FMI_VERSIONS, find_compiler, pack_fmu
from .plant_fmu import build_fmu, build_fmus
from .signal_fmu import SIGNAL_KINDS, SignalSpec, build_signal_fmu, channel_params, register_signal_kind

__all__ = ["FMI_VERSIONS", "SIGNAL_KINDS", "SignalSpec", "build_fmu", "build_fmus", "build_signal_fmu",
           "channel_params", "find_compiler", "pack_fmu", "register_signal_kind"]
