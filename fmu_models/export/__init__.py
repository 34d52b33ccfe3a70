"""Every FMU the project writes, in one place: plants (:mod:`.plant`), filters (:mod:`.filter`)
and signals (:mod:`.signal`), through one packer (:mod:`.pack`), one model-description
writer (:mod:`.description`), one variable list (:mod:`.variables`) and one
``model_config.h`` schema (:mod:`.config`) for the three C cores in ``c/``.

>>> from fmu_models.export import build_fmu
>>> path = build_fmu("cartpole", "fmus")            # doctest: +SKIP
"""
from .filter import export_filter_fmu, filter_parameters
from .pack import FMI_VERSIONS, find_compiler, pack_fmu
from .plant import build_fmu, build_fmus
from .signal import SIGNAL_KINDS, SignalSpec, build_signal_fmu, channel_params, register_signal_kind

__all__ = ["FMI_VERSIONS", "SIGNAL_KINDS", "SignalSpec", "build_fmu", "build_fmus", "build_signal_fmu",
           "channel_params", "export_filter_fmu", "filter_parameters", "find_compiler", "pack_fmu",
           "register_signal_kind"]
