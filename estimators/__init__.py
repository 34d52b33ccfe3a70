"""State estimators for the plant models of :mod:`fmu_models`.

Every filter has the interface of :class:`~estimators.base.KalmanBase`:
``predict(u)``, ``update(y)``, ``step(u, y)``, ``run(us, ys)`` (a whole record in native
code) and the attributes ``x, P, Q, R, innovation, S, K, nis``. Offline:
:func:`rts_smooth` (RTS smoothing of a run) and :func:`em_noise` (EM learning of Q, R).

>>> from fmu_models import get_model
>>> from estimators import EKF, discretize
>>> sys_ = discretize(get_model("cartpole"), dt=0.01)
>>> ekf = EKF(sys_, x0=[0.5, 0, 1.8, 0.5], P0=1.0, Q=0.2, R=0.1)
"""
from .base import FilterRun, KalmanBase
from .batch import BatchFilter, BatchRun
from .ekf import EKF
from .em import EMResult, em_noise
from .fuzzy import MamdaniFuzzy
from .iae import IAE
from .kf import KF
from .mfiae import MFIAE
from .smoother import Smoothed, rts_smooth
from .system import DiscreteModel, augment_rate_bias, discretize, linear_model
from .ukf import UKF

__all__ = ["EKF", "IAE", "KF", "MFIAE", "UKF", "BatchFilter", "BatchRun", "DiscreteModel", "EMResult",
           "FilterRun", "KalmanBase", "MamdaniFuzzy", "Smoothed", "augment_rate_bias", "discretize",
           "em_noise", "linear_model", "rts_smooth"]
