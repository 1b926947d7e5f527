"""Per-aircraft random streams for the fast tier's numba kernels (one uint64 state per sub-env).

Each sub-env owns one 64-bit state advanced by the SplitMix64 generator (Steele, Lea & Flood 2014, the
generator java.util.SplittableRandom uses): a sub-env's draws depend only on its own seed and its own
history, never on N or on the other sub-envs, so a seed fixes an episode bit for bit in any batch.
Normals by the Box-Muller transform.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

_GAMMA = uint64(0x9E3779B97F4A7C15)
_M1 = uint64(0xBF58476D1CE4E5B9)
_M2 = uint64(0x94D049BB133111EB)
_TWO_POW_M53 = 1.0 / 9007199254740992.0


@njit(cache=True)
def next_u64(state, i):
    """Advance sub-env i's state (uint64 array) and return the next 64-bit output."""
    z = state[i] + _GAMMA
    state[i] = z
    z = (z ^ (z >> uint64(30))) * _M1
    z = (z ^ (z >> uint64(27))) * _M2
    return z ^ (z >> uint64(31))


@njit(cache=True)
def uniform(state, i):
    """A uniform draw in [0, 1) (53 bits) from sub-env i's stream."""
    return float(next_u64(state, i) >> uint64(11)) * _TWO_POW_M53


@njit(cache=True)
def normal(state, i):
    """A standard normal draw from sub-env i's stream (Box-Muller, one of the pair)."""
    u1 = uniform(state, i)
    u2 = uniform(state, i)
    return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True)
def normal_pair(state, i):
    """Two independent standard normal draws from sub-env i's stream (Box-Muller, both of the pair)."""
    u1 = uniform(state, i)
    u2 = uniform(state, i)
    r = math.sqrt(-2.0 * math.log(1.0 - u1))
    return r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)


def seed_states(seeds) -> np.ndarray:
    """uint64 states from integer seeds (SeedSequence-hashed, so nearby seeds give unrelated streams)."""
    return np.array(
        [np.random.SeedSequence(int(s)).generate_state(1, np.uint64)[0] for s in seeds], np.uint64
    )
