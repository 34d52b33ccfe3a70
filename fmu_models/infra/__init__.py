"""The project's infrastructure, shared by :mod:`fmu_models`, :mod:`estimators` and :mod:`cosim` (it imports
none of them but :mod:`fmu_models.errors`); one module per job, named by what it is."""
