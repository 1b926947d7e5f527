"""The planner's search kernels (numba): A* over 16-connected moves on the cost map, with the featureless
stretch as part of the state when a bound is set (trn_env.guidance.planner states the cost J and the
constraints), its binary heap, and the featureless test of an edge.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# 16-connected moves (di, dj): the 8 neighbours and the 8 knight moves (headings every ~22.5 deg)
MOVES = np.array(
    [
        (1, 0),
        (-1, 0),
        (0, 1),
        (0, -1),
        (1, 1),
        (1, -1),
        (-1, 1),
        (-1, -1),
        (1, 2),
        (2, 1),
        (-1, 2),
        (-2, 1),
        (1, -2),
        (2, -1),
        (-1, -2),
        (-2, -1),
    ],
    dtype=np.int64,
)


FEATURELESS_EDGE = 0.5  # an edge with u_edge above this is featureless (extends the stretch)


@njit(cache=True)
def _heap_push(keys, vals, n, key, val):
    i = n
    keys[i] = key
    vals[i] = val
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] <= keys[i]:
            break
        keys[p], keys[i] = keys[i], keys[p]
        vals[p], vals[i] = vals[i], vals[p]
        i = p
    return n + 1


@njit(cache=True)
def _heap_pop(keys, vals, n):
    key, val = keys[0], vals[0]
    n -= 1
    keys[0] = keys[n]
    vals[0] = vals[n]
    i = 0
    while True:
        a = 2 * i + 1
        if a >= n:
            break
        b = a + 1
        c = b if (b < n and keys[b] < keys[a]) else a
        if keys[i] <= keys[c]:
            break
        keys[c], keys[i] = keys[i], keys[c]
        vals[c], vals[i] = vals[i], vals[c]
        i = c
    return key, val, n


@njit(cache=True)
def edge_featureless(u, i, j, di, dj):
    """Mean featureless factor of the cells an edge (i, j) -> (i + di, j + dj) touches: its two ends and,
    for a knight move, the two cells beside its midpoint."""
    s = u[i, j] + u[i + di, j + dj]
    n = 2.0
    if abs(di) == 2 or abs(dj) == 2:
        hi, hj = di // 2 if abs(di) == 2 else 0, dj // 2 if abs(dj) == 2 else 0
        ai, aj = i + hi, j + hj
        bi, bj = i + di - hi, j + dj - hj
        if abs(di) == 1:
            ai, bi = i, i + di
        if abs(dj) == 1:
            aj, bj = j, j + dj
        s += u[ai, aj] + u[bi, bj]
        n = 4.0
    return s / n


@njit(cache=True)
def astar_kernel(grid, search, start, goal):
    """A* over states (cell, featureless-stretch bin); returns (cost, path as (n, 2) cells; empty if none).

    Records (numba tuples): grid = (u featureless measure, height m, blocked, cell_n_m, cell_e_m) per cell;
    search = (moves, weight, bounded, n_bins, bin_m, climb_max); start, goal = (i, j) cells.
    bounded False: no featureless bound (n_bins 1). Else a state's bin is round(stretch / bin_m) and a
    featureless edge that would take it to n_bins or beyond is not allowed. climb_max <= 0: no climb limit."""
    u, height, blocked, cell_n_m, cell_e_m = grid
    moves, weight, bounded, n_bins, bin_m, climb_max = search
    si, sj = start
    gi, gj = goal
    ni, nj = u.shape
    n_states = ni * nj * n_bins
    g = np.full(n_states, np.inf)
    parent = np.full(n_states, -1, np.int64)
    done = np.zeros(n_states, np.bool_)
    cap = n_states * moves.shape[0] + 1
    keys = np.empty(cap)
    vals = np.empty(cap, np.int64)
    lengths = np.empty(moves.shape[0])
    for m in range(moves.shape[0]):
        lengths[m] = math.hypot(moves[m, 0] * cell_n_m, moves[m, 1] * cell_e_m)
    s0 = (si * nj + sj) * n_bins
    g[s0] = 0.0
    h0 = 0.999 * math.hypot((gi - si) * cell_n_m, (gj - sj) * cell_e_m)
    n = _heap_push(keys, vals, 0, h0, s0)
    goal_state = -1
    while n > 0:
        _, s, n = _heap_pop(keys, vals, n)
        if done[s]:
            continue
        done[s] = True
        cell = s // n_bins
        b = s - cell * n_bins
        i = cell // nj
        j = cell - i * nj
        if i == gi and j == gj:
            goal_state = s
            break
        for m in range(moves.shape[0]):
            di, dj = moves[m, 0], moves[m, 1]
            ii, jj = i + di, j + dj
            if ii < 0 or ii >= ni or jj < 0 or jj >= nj or blocked[ii, jj]:
                continue
            if climb_max > 0.0 and (height[ii, jj] - height[i, j]) > climb_max * lengths[m]:
                continue
            ue = edge_featureless(u, i, j, di, dj)
            nb = 0
            if bounded and ue > FEATURELESS_EDGE:
                nb = int(round(b * 1.0 + lengths[m] / bin_m))
                if nb >= n_bins:
                    continue
            t = (ii * nj + jj) * n_bins + nb
            if done[t]:
                continue
            gt = g[s] + lengths[m] * (1.0 + weight * ue)
            if gt < g[t]:
                g[t] = gt
                parent[t] = s
                ht = 0.999 * math.hypot((gi - ii) * cell_n_m, (gj - jj) * cell_e_m)
                n = _heap_push(keys, vals, n, gt + ht, t)
    if goal_state < 0:
        return np.inf, np.zeros((0, 2), np.int64)
    count = 0
    s = goal_state
    while s >= 0:
        count += 1
        s = parent[s]
    path = np.empty((count, 2), np.int64)
    s = goal_state
    k = count - 1
    while s >= 0:
        cell = s // n_bins
        path[k, 0] = cell // nj
        path[k, 1] = cell - (cell // nj) * nj
        k -= 1
        s = parent[s]
    return g[goal_state], path


@njit(cache=True)
def path_stretch_bins(u, path, cell_n_m, cell_e_m, bin_m):
    """The highest featureless-stretch bin a cell path reaches, counted as astar_kernel counts it (a
    featureless edge takes the bin to round(bin + length / bin_m), an informative one back to 0): the path
    is a bounded search's answer only if this is below its n_bins."""
    b = 0
    top = 0
    for k in range(path.shape[0] - 1):
        i, j = path[k, 0], path[k, 1]
        di, dj = path[k + 1, 0] - i, path[k + 1, 1] - j
        if edge_featureless(u, i, j, di, dj) > FEATURELESS_EDGE:
            b = int(round(b * 1.0 + math.hypot(di * cell_n_m, dj * cell_e_m) / bin_m))
        else:
            b = 0
        if b > top:
            top = b
    return top


@njit(cache=True)
def _featureless_runs(ds, feat):
    """(longest, final) featureless stretch (m) of samples with lengths ds and featureless flags feat."""
    run = 0.0
    longest = 0.0
    for k in range(ds.shape[0]):
        run = run + ds[k] if feat[k] else 0.0
        if run > longest:
            longest = run
    return longest, run
