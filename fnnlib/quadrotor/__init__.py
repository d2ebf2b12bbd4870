"""The paper's Sec. 5 stack: the quadrotor of Eq. (27), learning its aerodynamic residual, and MPC with it.

A user of the method (:mod:`fnnlib`'s face) never needs this part. Its modules:

* :mod:`~fnnlib.quadrotor.presets`: every Sec. 5 setting of the paper (App. A.5, the authors' release),
  written once;
* :mod:`fnnlib.systems.quadrotor`, :mod:`fnnlib.systems.rotations`, :mod:`fnnlib.systems.allocation`: the
  vehicle of Eq. (27), its attitude algebra and its motor allocation;
* :mod:`fnnlib.models.residual`, :mod:`fnnlib.training.residual`, :mod:`fnnlib.data.quadrotor`: the
  aerodynamic residual networks, their training and the flight data (Sec. 5.2);
* :mod:`fnnlib.control`: the reference trajectories and the differential-flatness controller;
* :mod:`fnnlib.mpc`: MPC with the nominal, neural, feedback and adaptive models (Sec. 5.3, App. A.5).
"""
