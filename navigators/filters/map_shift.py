"""The share of the map's horizontal shift in a terrain filter's published position.

A map shifted by s (a feature at true position p appears at p + s; terrain.map_error) moves every terrain
fix by s: terrain samples pin the position relative to the map, not to the Earth, and no amount of them
shows the filter the shift. The point-mass and particle filters' belief is therefore the position's error
relative to the map; the published position's error, relative to the Earth, is

    e = e_f + A s,   A = diag(a_n, a_e) (a 2 x 2 matrix once carried states mix the axes, below),

e_f the part the belief describes (INS drift, sensor noise) and a_i in [0, 1] the share of the shift the
estimate has taken on along each axis. Per axis, a measurement update with gain k moves the estimate by k
times its residual, so (the fixed-gain error recursion, exact for a scalar Kalman update, where
k = 1 - P_post / P_prior):

- a terrain sample, which sees x + s:  a' = (1 - k) a + k;
- a GNSS fix, which sees x:            a' = (1 - k) a;
- prediction (the INS walk, the grid's convolution, re-spreading the belief around its mean) leaves a:
  the estimate keeps the shift it took while e_f grows.

A GNSS fix is a measurement of the position relative to the Earth, whose error holds a s: fused against the
belief alone (the error relative to the map, a few metres after terrain samples) a fix sigma_h away would
be an outlier to it. So before a fix the filters widen the belief by the share's covariance and set a to 0
(terrain_filter._shift_into_belief: the share becomes the belief's own, which the fix then narrows as a
Bayes update does), so the filters need no GNSS step of the recursion: it runs from 0 again. (`gnss`
states it for a filter that fuses fixes without the widening.)

A filter that carries other states whose means follow the position's (the point-mass filter's velocity,
tilt, accelerometer-bias and heading offsets u, moved by the Gaussian regression on the grid's moments,
u_mean += G dx_mean) takes part of the shift into them, and its prediction moves the position by B u_mean:
the shift then reaches the position later through them, which a rule on the position's variance alone
does not see (docs/validation/integrity.md, section 7.1). With U the carried states' share (u's error
holds U s), a terrain update also moves U by G dA (dA the position's share change), and a prediction
moves A by B U and U to F U (F u's transition): the fixed-gain error recursion of the whole linear model.
Before a GNSS fix the widening covers both: sigma_h^2 [A; U] [A; U]'.

A particle update is a reweighting, and its variance change need not follow its mean's response to the
measurement (a likelihood curved over the cloud narrows it without moving its mean, so k from the variances
overstates the gain). The Rao-Blackwellised particle filter therefore takes the mean's own response
(`particle_mean_response`): with prior and posterior weights w, w+ and each particle's score
g_i = d log p(y | i) / dy, the posterior mean m+ = sum w+_i x_i moves with the measurement by
dm+/dy = sum w+_i (x_i - m+) g_i' (exact: the derivative of the weights), and the shift moves the
measurement by H s, H = Cov(y_hat, x) P^-1 the cloud's regression of its predicted measurements on its
position; M = (dm+/dy) H and A' = A + M (I - A) (`MapShiftShare.respond`), the fixed-gain recursion with
K H = M, which it equals for a linear-Gaussian update. (The particle filter keeps the variance rule: with the
mean's response its published covariance over DTED-1 maps was the less consistent: docs/validation/
integrity.md, section 7.1.)

The grid and particle updates are not linear: k is taken per axis from the belief's variance before and
after the update, clipped to [0, 1] (a multimodal posterior can be wider than its prior); A's row i moves
toward the unit row by k_i. s is independent of e_f with variance sigma_h^2 per axis (the map's accuracy
class: CE90 / 2.146), so the published horizontal covariance adds sigma_h^2 A A' to the belief's (diag(a_n^2,
a_e^2) sigma_h^2 without carried states). Navigators hold sigma_h as `map_horizontal_sigma_m`
(navigators.registry's published-integrity setting, which the protection level already bounds
separately: navigators.integrity.protection_level.publish); with it 0 nothing changes.
"""

from __future__ import annotations

import math

import numpy as np


def _gain(var_prior: float, var_post: float) -> float | None:
    """1 - var_post / var_prior clipped to [0, 1]; None when either is not a finite positive variance."""
    if not (math.isfinite(var_prior) and math.isfinite(var_post)) or var_prior <= 0.0 or var_post < 0.0:
        return None
    return min(max(1.0 - var_post / var_prior, 0.0), 1.0)


def particle_mean_response(x: np.ndarray, w_prior: np.ndarray, w_post: np.ndarray, score: np.ndarray,
                           y_hat: np.ndarray) -> np.ndarray | None:
    """M = (dm+/dy) H (2 x 2) of a weighted-particle update (see the module): x (n, 2) the particles'
    horizontal positions (m; any origin or sign, M is the same), w_prior, w_post (n,) their weights before
    and after (normalised here; both 0 for a particle without a prediction), score (n, m)
    d log p(y | particle) / dy and y_hat (n, m) their predicted measurements (any common offset). None when
    the prior cloud's horizontal covariance is not positive definite or anything is not finite."""
    x = np.asarray(x, float)
    w0 = np.asarray(w_prior, float)
    w1 = np.asarray(w_post, float)
    if not (w0.sum() > 0.0 and w1.sum() > 0.0):
        return None
    w0 = w0 / w0.sum()
    w1 = w1 / w1.sum()
    use = (w0 > 0.0) | (w1 > 0.0)
    x, w0, w1 = x[use], w0[use], w1[use]
    score, y_hat = np.asarray(score, float)[use], np.asarray(y_hat, float)[use]
    score = np.where(w1[:, None] > 0.0, score, 0.0)               # a particle the update dropped: no say
    m1 = w1 @ x
    dm_dy = (w1[:, None] * (x - m1)).T @ score                    # 2 x m
    m0 = w0 @ x
    d0 = x - m0
    P0 = (w0[:, None] * d0).T @ d0
    C_yx = (w0[:, None] * (y_hat - w0 @ y_hat)).T @ d0            # m x 2
    try:
        if np.linalg.eigvalsh(P0)[0] <= 0.0:
            return None
        H = np.linalg.solve(P0, C_yx.T).T
    except np.linalg.LinAlgError:
        return None
    M = dm_dy @ H
    return M if np.all(np.isfinite(M)) else None


class MapShiftShare:
    """The share of the map's horizontal shift s (north, east) in the estimate (see the module): A (2 x 2),
    the position's error holding A s, and U (n x 2), the filter's carried states' means holding U s (none:
    n = 0). Built with per-axis shares `share` (A = diag(share))."""

    def __init__(self, share=(0.0, 0.0), n_carried: int = 0) -> None:
        self.A = np.diag(np.asarray(share, float))
        self.U = np.zeros((int(n_carried), 2))

    @property
    def share(self) -> np.ndarray:
        """The per-axis shares (a_n, a_e): A's diagonal."""
        return np.diag(self.A).copy()

    def any(self) -> bool:
        """Whether any of the shift is in the estimate."""
        return bool(np.any(self.A != 0.0) or np.any(self.U != 0.0))

    def reset(self) -> None:
        """None of the shift in the estimate (after it has been moved into the belief)."""
        self.A[:] = 0.0
        self.U[:] = 0.0

    def terrain(self, cov_prior: np.ndarray, cov_post: np.ndarray,
                regression: np.ndarray | None = None) -> None:
        """A terrain update took the belief's horizontal covariance (2 x 2 or larger, m^2, north-east
        first) from cov_prior to cov_post; `regression` (n x 2): how the carried states' means moved per
        metre of the position's mean (the filter's Gaussian regression on its position)."""
        self._update(cov_prior, cov_post, 1.0, regression)

    def gnss(self, cov_prior: np.ndarray, cov_post: np.ndarray,
             regression: np.ndarray | None = None) -> None:
        """A GNSS position update took the belief's horizontal covariance from cov_prior to cov_post."""
        self._update(cov_prior, cov_post, 0.0, regression)

    def _update(self, cov_prior, cov_post, toward: float, regression) -> None:
        before = self.A.copy()
        for i in range(2):
            k = _gain(float(cov_prior[i, i]), float(cov_post[i, i]))
            if k is not None:
                self.A[i] = (1.0 - k) * self.A[i]
                self.A[i, i] += k * toward
        if regression is not None and self.U.size:
            self.U += np.asarray(regression, float) @ (self.A - before)

    def respond(self, M: np.ndarray) -> None:
        """A terrain update whose mean moves by M (2 x 2, K H of a linear update) per metre of the map's
        shift the measurement sees: A' = A + M (I - A) (`particle_mean_response`)."""
        self.A = self.A + np.asarray(M, float) @ (np.eye(2) - self.A)

    def predict(self, B: np.ndarray, F: np.ndarray) -> None:
        """Prediction of a filter whose position mean moves by B u (B: 2 x n) and whose carried states'
        mean goes to F u (n x n): the shift's share moves with them."""
        if not np.any(self.U != 0.0):
            return
        self.A += B @ self.U
        self.U = F @ self.U

    def covariance(self, sigma_h_m: float) -> np.ndarray:
        """The shift's part of the published horizontal covariance (2 x 2, m^2) for a shift of sigma_h_m per
        axis: sigma_h^2 A A'."""
        return self.A @ self.A.T * float(sigma_h_m) ** 2

    def carried_covariances(self, sigma_h_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The shift's part of the carried states' covariance with the position (n x 2) and of their own
        (n x n), m^2 and state units, for a shift of sigma_h_m per axis: sigma_h^2 U A', sigma_h^2 U U'."""
        s2 = float(sigma_h_m) ** 2
        return self.U @ self.A.T * s2, self.U @ self.U.T * s2
