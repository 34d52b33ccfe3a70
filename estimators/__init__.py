"""State estimators (KF, EKF, UKF, IAE, MF-IAE) for the plant models of `fmu_models`."""
