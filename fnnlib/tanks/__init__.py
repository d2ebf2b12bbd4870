"""The cascaded tanks benchmark, a real plant beyond the paper: what its chapter measures on a learned model.

* :mod:`~fnnlib.tanks.evaluation`: the seeds' trainings as one stacked ensemble and their validation, every
  horizon of the cascade of Sec. 3.3 from one run, the no-feedback baseline, the N-step output RMSE, the free
  run (Eq. (8) without its correction after the first samples), the Kalman filters' N-step table, the overflow
  episodes.

The benchmark's records and metric are :mod:`fnnlib.data.tanks`, its synthetic twin
:mod:`fnnlib.systems.tanks`, the linear ARX baseline :mod:`fnnlib.models.arx`.
"""
