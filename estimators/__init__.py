"""State estimators for the plant models of :mod:`fmu_models` (the manual's estimators page shows their use).
"""
from fmu_models.infra.version import VERSION as __version__

from .base import FILTERS, KalmanBase
from .batch import BatchFilter
from .consistency import BandTest, WhitenessTest, chi2_band, nees_test, nis_test, whiteness_test
from .discrete import DiscreteModel, augment_rate_bias, discretize, linear_model
from .ekf import EKF
from .em import em_noise
from .filter_fmu import export_filter_fmu
from .fmu_model import FMUProcessModel
from .fuzzy import MamdaniFuzzy
from .iae import IAE
from .kf import KF
from .mfiae import MFIAE
from .pcrb import PCRB, posterior_crb, rmse_ratio
from .protocol import Parameter, StepContext, StepResult, Update
from .runs import BatchRun, EMResult, FilterRun, Smoothed
from .smoother import rts_smooth
from .swml import SWML
from .ukf import UKF

__all__ = ["EKF", "FILTERS", "IAE", "KF", "MFIAE", "PCRB", "SWML", "UKF", "BandTest", "BatchFilter", "BatchRun",
           "DiscreteModel", "EMResult", "FMUProcessModel", "FilterRun", "KalmanBase", "MamdaniFuzzy", "Parameter",
           "Smoothed", "StepContext", "StepResult", "Update", "WhitenessTest", "__version__", "augment_rate_bias",
           "chi2_band", "discretize", "em_noise", "export_fmu", "linear_model", "nees_test", "nis_test",
           "posterior_crb", "rmse_ratio", "rts_smooth", "whiteness_test"]


def export_fmu(filt, out_dir=".", fmi_version: int = 2, name=None, file_name=None, clocked: bool = False):
    """Export the filter ``filt`` as a Co-Simulation FMU: :func:`estimators.filter_fmu.export_filter_fmu`
    with the same parameters (``filt``, ``out_dir``, ``fmi_version``, ``name``, ``file_name``, ``clocked``)."""
    return export_filter_fmu(filt, out_dir, fmi_version, name, file_name, clocked)
