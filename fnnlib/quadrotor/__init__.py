"""The paper's Sec. 5 stack: the quadrotor of Eq. (27), learning its aerodynamic residual, and MPC with it.

A user of the method (:mod:`fnnlib`'s face) never needs this part, and the method's own subpackages
(:mod:`fnnlib.systems`, :mod:`fnnlib.models`, :mod:`fnnlib.training`) do not import it. Its modules:

* :mod:`~fnnlib.quadrotor.presets`: every Sec. 5 setting of the paper (App. A.5, the authors' release),
  written once;
* :mod:`fnnlib.quadrotor.system`, :mod:`fnnlib.quadrotor.rotations`, :mod:`fnnlib.quadrotor.allocation`: the
  vehicle of Eq. (27), its attitude algebra and its motor allocation;
* :mod:`fnnlib.quadrotor.residual`, :mod:`fnnlib.quadrotor.training`, :mod:`fnnlib.data.quadrotor`: the
  aerodynamic residual networks, their training and the flight data (Sec. 5.2);
* :mod:`fnnlib.quadrotor.control`: the reference trajectories and the differential-flatness controller;
* :mod:`fnnlib.quadrotor.mpc`: MPC with the nominal, neural, feedback and adaptive models (Sec. 5.3, App. A.5);
* :mod:`~fnnlib.quadrotor.evaluation`: the flight records of the why grid (Sec. 5.2.2, App. A.9).
"""
