"""Terrain-aided filters over the INS.

ins_trn_ekf   `InsTrnNavigator`: INS + batch TERCOM fixes + 13-state error-state EKF (seed 000)
_ekf_kernels  its numba kernels
terrain_filter `InsRiddenFilter`: what the PMF and the PF share (INS, measurement epochs, GNSS, Health)
pmf           `PointMassFilter` ("pmf"): grid over the horizontal position error, per-cell vertical offset
pf            `ParticleFilter` ("pf"): SIR over position, vertical offset, velocity and heading errors
resampling    systematic resampling (numba) with a required Generator, effective sample size
_pf_kernels   the particle filter's propagation kernel
"""

from .ins_trn_ekf import InsTrnNavigator, initial_covariance
from .pf import ParticleFilter
from .pmf import PointMassFilter

__all__ = ["InsTrnNavigator", "ParticleFilter", "PointMassFilter", "initial_covariance"]
