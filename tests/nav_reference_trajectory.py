"""An exact manoeuvring reference trajectory and its perfect IMU data, computed in ECEF (independent of the
NED mechanisation, navigators.inertial): f = r'' + 2 W x r' + W x (W x r) - G_J2(r), w_ib = w_eb + C_eb W."""

import numpy as np

A = 6378137.0
E2 = 6.69437999014e-3
OMEGA = 7.292115e-5
FT = 0.3048
GM = 14.0764417572e15 * FT**3  # JSBSim FGInertia
J2 = 1.08262982e-3
A_J2 = 20925646.32546 * FT


def lla_to_ecef(lat, lon, h):
    re = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (re + h) * np.cos(lat) * np.cos(lon),
            (re + h) * np.cos(lat) * np.sin(lon),
            (re * (1 - E2) + h) * np.sin(lat),
        ],
        -1,
    )


def gravitation_j2(r):
    rn = np.linalg.norm(r, axis=-1)
    s = r[..., 2] / rn
    pre = 1.5 * J2 * (A_J2 / rn) ** 2
    k = -GM / rn**3
    return np.stack(
        [
            k * (1 + pre * (1 - 5 * s * s)) * r[..., 0],
            k * (1 + pre * (1 - 5 * s * s)) * r[..., 1],
            k * (1 + pre * (3 - 5 * s * s)) * r[..., 2],
        ],
        -1,
    )


def C_en(lat, lon):
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    c = np.empty(lat.shape + (3, 3))
    c[..., :, 0] = np.stack([-sl * co, -sl * so, cl], -1)
    c[..., :, 1] = np.stack([-so, co, 0 * lat], -1)
    c[..., :, 2] = np.stack([-cl * co, -cl * so, -sl], -1)
    return c


def C_bn(r, p, y):
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack(
        [
            np.stack([cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy], -1),
            np.stack([cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy], -1),
            np.stack([-sp, sr * cp, cr * cp], -1),
        ],
        -2,
    )


LAT0, LON0, H0 = np.radians(33.2), np.radians(-98.1), 3000.0


def lla(t):
    n = 90 * t + 800 * np.sin(2 * np.pi * t / 150)
    e = 1500 * np.sin(2 * np.pi * t / 200) + 20 * t
    h = H0 + 150 * np.sin(2 * np.pi * t / 90)
    return LAT0 + n / 6.37e6, LON0 + e / (6.37e6 * np.cos(LAT0)), h


def euler(t):
    return (
        0.4 * np.sin(2 * np.pi * t / 60),
        0.05 + 0.05 * np.sin(2 * np.pi * t / 45),
        0.5 * np.sin(2 * np.pi * t / 200) + 0.3 * np.sin(2 * np.pi * t / 33),
    )


def _d(fun, t, k, h):
    """k-th derivative (k = 1, 2) by fourth-order central differences."""
    fm2, fm1, fp1, fp2 = fun(t - 2 * h), fun(t - h), fun(t + h), fun(t + 2 * h)
    if k == 1:
        return (-fp2 + 8 * fp1 - 8 * fm1 + fm2) / (12 * h)
    f0 = fun(t)
    return (-fp2 + 16 * fp1 - 30 * f0 + 16 * fm1 - fm2) / (12 * h * h)


def imu_and_truth(t, lla=lla, euler=euler):
    """Perfect IMU samples at times t and the truth (lat, lon, h, v_ned, euler) of the trajectory given by
    the functions lla(t) -> (lat, lon, h) and euler(t) -> (roll, pitch, yaw)."""
    r_of = lambda tt: lla_to_ecef(*lla(tt))  # noqa: E731
    r = r_of(t)
    rd = _d(r_of, t, 1, 0.05)
    rdd = _d(r_of, t, 2, 0.05)
    W = np.array([0, 0, OMEGA])
    f_e = rdd + 2 * np.cross(W, rd) + np.cross(W, np.cross(W, r)) - gravitation_j2(r)
    lat, lon, h = lla(t)
    Cbe_of = lambda tt: C_en(*lla(tt)[:2]) @ C_bn(*euler(tt))  # noqa: E731
    Cbe = Cbe_of(t)
    Cdot = _d(Cbe_of, t, 1, 0.01)
    Om = np.swapaxes(Cbe, -1, -2) @ Cdot
    w_eb = np.stack(
        [
            0.5 * (Om[:, 2, 1] - Om[:, 1, 2]),
            0.5 * (Om[:, 0, 2] - Om[:, 2, 0]),
            0.5 * (Om[:, 1, 0] - Om[:, 0, 1]),
        ],
        -1,
    )
    w_ib = w_eb + np.einsum("nji,j->ni", Cbe, W)
    f_b = np.einsum("nji,nj->ni", Cbe, f_e)
    v_ned = np.einsum("nji,nj->ni", C_en(lat, lon), rd)
    return f_b, w_ib, (lat, lon, h, v_ned, euler(t))
