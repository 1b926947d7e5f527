"""The true flight, in SI units, one row per JSBSim step.

The flight core fills a `TruthChunk` from cached JSBSim property nodes; sensors, logs, rewards and
`info` read it. Navigators never see it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields

import numpy as np

# name -> trailing shape of each per-step field (the leading axis is the step index).
TRUTH_FIELDS: dict[str, tuple[int, ...]] = {
    "t_s": (),              # seconds since scenario start
    "lat_rad": (),          # WGS84 geodetic latitude
    "lon_rad": (),          # WGS84 longitude
    "h_msl_m": (),          # height above MSL (the DEM's vertical datum), metres
    "v_ned_mps": (3,),      # velocity relative to the Earth in NED, m/s
    "roll_rad": (),         # 3-2-1 Euler angles of the body (FRD) relative to NED
    "pitch_rad": (),
    "yaw_rad": (),          # true heading, (-pi, pi]
    "C_bn": (3, 3),         # rotation body (FRD) -> NED
    "omega_ib_b_rps": (3,),  # body angular rate relative to inertial space, body axes (what gyros sense)
    "omega_eb_b_rps": (3,),  # body angular rate relative to the Earth, body axes (JSBSim p, q, r)
    "f_b_mps2": (3,),       # specific force at the IMU location, body axes (what accelerometers sense)
    "tas_mps": (),          # true airspeed
    "alpha_rad": (),        # angle of attack
    "beta_rad": (),         # sideslip angle
    "p_static_pa": (),      # ambient static pressure
    "T_static_K": (),       # ambient static temperature
    "wind_ned_mps": (3,),   # total wind (steady + turbulence + gust) in NED, m/s
    "h_agl_m": (),          # height above the terrain JSBSim knows (written by guidance), metres
}


@dataclass
class TruthChunk:
    """Per-step true state for steps [0, n). All arrays share the leading length n."""

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    h_msl_m: np.ndarray
    v_ned_mps: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    C_bn: np.ndarray
    omega_ib_b_rps: np.ndarray
    omega_eb_b_rps: np.ndarray
    f_b_mps2: np.ndarray
    tas_mps: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    p_static_pa: np.ndarray
    T_static_K: np.ndarray
    wind_ned_mps: np.ndarray
    h_agl_m: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @classmethod
    def empty(cls, n: int) -> TruthChunk:
        """Preallocated chunk of n steps (filled with NaN)."""
        return cls(**{k: np.full((n,) + shape, np.nan) for k, shape in TRUTH_FIELDS.items()})

    def slice(self, start: int, stop: int) -> TruthChunk:
        """Rows [start, stop) as views."""
        return TruthChunk(**{f.name: getattr(self, f.name)[start:stop] for f in fields(self)})

    def copy(self) -> TruthChunk:
        return TruthChunk(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    @staticmethod
    def concatenate(chunks: list[TruthChunk]) -> TruthChunk:
        return TruthChunk(**{k: np.concatenate([getattr(c, k) for c in chunks]) for k in TRUTH_FIELDS})

    @staticmethod
    def from_blocks(scalars: np.ndarray, vectors: np.ndarray, C_bn: np.ndarray) -> TruthChunk:
        """A chunk over three blocks, without building its per-field views yet (the flight core's fast
        path): scalars (len(SCALAR_FIELDS), n), row k = SCALAR_FIELDS[k]; vectors (len(VECTOR_FIELDS), 3, n),
        field k = vectors[k].T (an (n, 3) view); C_bn (n, 3, 3). All views are built together on the first
        access of any field; the result behaves as a TruthChunk in every other respect."""
        chunk = _BlockTruthChunk.__new__(_BlockTruthChunk)
        chunk.__dict__["_blocks"] = (scalars, vectors, C_bn)
        return chunk


# Row order of TruthChunk.from_blocks' blocks.
SCALAR_FIELDS: tuple[str, ...] = ("t_s", "lat_rad", "lon_rad", "h_msl_m", "roll_rad", "pitch_rad", "yaw_rad",
                                  "tas_mps", "alpha_rad", "beta_rad", "p_static_pa", "T_static_K", "h_agl_m")
VECTOR_FIELDS: tuple[str, ...] = ("v_ned_mps", "omega_ib_b_rps", "omega_eb_b_rps", "f_b_mps2", "wind_ned_mps")


class _BlockView:
    """Non-data descriptor standing for one field of a _BlockTruthChunk until its views are built (the
    instance attributes then take precedence, so later accesses are plain attribute lookups)."""

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        return obj._build_views()[self.name]


class _BlockTruthChunk(TruthChunk):
    """TruthChunk whose field views are made from its blocks on first access (see TruthChunk.from_blocks).
    Once built they are ordinary instance attributes; constructing it with field values (dataclasses.replace)
    gives ordinary instance attributes too."""

    def _build_views(self) -> dict:
        d = self.__dict__
        scalars, vectors, c_bn = d["_blocks"]
        (t_s, lat_rad, lon_rad, h_msl_m, roll_rad, pitch_rad, yaw_rad, tas_mps, alpha_rad, beta_rad,
         p_static_pa, T_static_K, h_agl_m) = scalars
        v_ned_mps, omega_ib_b_rps, omega_eb_b_rps, f_b_mps2, wind_ned_mps = vectors.transpose(0, 2, 1)
        d.update(t_s=t_s, lat_rad=lat_rad, lon_rad=lon_rad, h_msl_m=h_msl_m, v_ned_mps=v_ned_mps,
                 roll_rad=roll_rad, pitch_rad=pitch_rad, yaw_rad=yaw_rad, C_bn=c_bn,
                 omega_ib_b_rps=omega_ib_b_rps, omega_eb_b_rps=omega_eb_b_rps, f_b_mps2=f_b_mps2,
                 tas_mps=tas_mps, alpha_rad=alpha_rad, beta_rad=beta_rad, p_static_pa=p_static_pa,
                 T_static_K=T_static_K, wind_ned_mps=wind_ned_mps, h_agl_m=h_agl_m)
        return d

    def __reduce__(self):
        """Pickled as its three blocks (the views share their memory, so edits made through them are kept),
        or field by field when it was built from field values."""
        blocks = self.__dict__.get("_blocks")
        if blocks is not None:
            return (TruthChunk.from_blocks, blocks)
        return (_from_fields, ({f.name: getattr(self, f.name) for f in fields(self)},))


class StepClock:
    """The flight time both flights (trn_env.flight.core.Flight, kinematic.KinematicFlight) report: _steps
    steps of dt_s seconds taken since the start."""

    _steps: int
    dt_s: float

    @property
    def t_s(self) -> float:
        """Time since the start of the flight (s)."""
        return self._steps * self.dt_s

    @property
    def steps(self) -> int:
        """Steps taken since the start of the flight."""
        return self._steps


def _from_fields(values: dict) -> TruthChunk:
    return TruthChunk(**values)


_BUFFER_HEADER = struct.Struct("<qq")    # rows, one caller's integer


def chunk_to_buffer(chunk: TruthChunk, tag: int = 0) -> bytearray:
    """The chunk's numbers as one buffer (its three blocks, float64, after a header of the row count and
    `tag`), for another process: copying 30 kB is cheaper than pickling twenty arrays (see
    chunk_from_buffer)."""
    blocks = chunk.__dict__.get("_blocks")
    if blocks is None:
        blocks = (np.stack([getattr(chunk, f) for f in SCALAR_FIELDS]),
                  np.stack([getattr(chunk, f).T for f in VECTOR_FIELDS]), chunk.C_bn)
    n = len(chunk)
    sizes = [8 * n * w for w in _BLOCK_WIDTHS]
    buf = bytearray(_BUFFER_HEADER.size + sum(sizes))
    _BUFFER_HEADER.pack_into(buf, 0, n, tag)
    offset = _BUFFER_HEADER.size
    for block, size in zip(blocks, sizes, strict=True):
        np.frombuffer(buf, np.float64, size // 8, offset)[:] = np.ascontiguousarray(block).ravel()
        offset += size
    return buf


def chunk_from_buffer(buf: bytearray) -> tuple[TruthChunk, int]:
    """(chunk, tag) from chunk_to_buffer's buffer; the chunk's arrays are views of `buf` (keep it private)."""
    n, tag = _BUFFER_HEADER.unpack_from(buf, 0)
    offset = _BUFFER_HEADER.size
    arrays = []
    for width in _BLOCK_WIDTHS:
        arrays.append(np.frombuffer(buf, np.float64, n * width, offset))
        offset += 8 * n * width
    scalars = arrays[0].reshape(len(SCALAR_FIELDS), n)
    vectors = arrays[1].reshape(len(VECTOR_FIELDS), 3, n)
    c_bn = arrays[2].reshape(n, 3, 3)
    return TruthChunk.from_blocks(scalars, vectors, c_bn), tag


_BLOCK_WIDTHS = (len(SCALAR_FIELDS), 3 * len(VECTOR_FIELDS), 9)   # float64 per row of each block

for _name in TRUTH_FIELDS:
    setattr(_BlockTruthChunk, _name, _BlockView(_name))
del _name
assert SCALAR_FIELDS == ("t_s", "lat_rad", "lon_rad", "h_msl_m", "roll_rad", "pitch_rad", "yaw_rad",
                         "tas_mps", "alpha_rad", "beta_rad", "p_static_pa", "T_static_K", "h_agl_m")
assert VECTOR_FIELDS == ("v_ned_mps", "omega_ib_b_rps", "omega_eb_b_rps", "f_b_mps2", "wind_ned_mps")
assert set(SCALAR_FIELDS) | set(VECTOR_FIELDS) | {"C_bn"} == set(TRUTH_FIELDS)
