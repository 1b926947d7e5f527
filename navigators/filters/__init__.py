"""Terrain-aided filters over the INS.

ins_trn_ekf   `InsTrnNavigator`: INS + batch TERCOM fixes + 13-state error-state EKF (seed 000)
_ekf_kernels  its numba kernels
"""

from navigators.filters.ins_trn_ekf import InsTrnNavigator, initial_covariance

__all__ = ["InsTrnNavigator", "initial_covariance"]
