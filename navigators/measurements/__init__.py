"""Measurement models shared by the navigators, by sensor.

Each sensor's module predicts the measurement of a state or of many hypotheses over arrays and gives the
filters what they update with: a Jacobian (the EKF's) or a log-likelihood per hypothesis (the grid and
particle filters').

radar_altimeter    terrain clearance under hypotheses: `predict` (the shortest in-cone range on the map),
                   `variance`, `likelihood` (seed 000 eq 1)
ira                the IRA with the seeds' variants: seed 000's closest points over hypotheses
                   (`closest_points`), `predict` (map height there), `variance`, `likelihood`; seed 002's
                   (R, theta) on the zero-Doppler line, `predict_seed002` and `jacobian_seed002` (eqs 23-26)
ira_closest_point  seed 000's closest-point formulas for single samples: (R, theta) + attitude + velocity ->
                   the return's position relative to the antenna (eqs 3-13, 14-36)
ira_seed002        seed 002's zero-Doppler search and its linearisation (behind ira.predict_seed002)
ira_map_noise      the map's height errors as IRA noise (seed 002: flat-ground model, its calibration per map)
gnss               GNSS position and velocity fix against the INS: `residual`, `jacobian`, `noise` (EKF);
                   `predict`, `likelihood` (grid and particle filters)
baro               the barometric altimeter: geopotential (pressure) altitude to geometric height, `predict`
                   (the reading of a height hypothesis with a bias), `likelihood`
lever_arm          lever arms of the ranging antennas transferred to the IMU point
terrain_models     what the terrain sensors share: the radii at a reference, the heavy-tailed likelihood
sampling           the terrain samples a filter takes from a frame (valid returns, at most one per interval)
"""

from .ira_closest_point import (
    FORMULAS,
    closest_point_ned,
    effective_look_angle,
)
from .terrain_models import radii_m, robust_log_likelihood

__all__ = ["FORMULAS", "closest_point_ned", "effective_look_angle", "radii_m", "robust_log_likelihood"]
