"""What keeps the first run's compile short (issue 21 section 2): no numba IR inlining, and one
specialisation where integer constants are passed to a kernel. (Compile times themselves are figures in
docs/guide/first_flight.md, measured by scripts, never asserted.)"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _inline_always_uses() -> list[str]:
    hits = []
    for pkg in ("terrain", "navigators", "trn_env"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.keyword) and node.arg == "inline":
                    if isinstance(node.value, ast.Constant) and node.value.value == "always":
                        hits.append(f"{path.relative_to(ROOT)}:{node.value.lineno}")
    return hits


def test_no_numba_ir_inlining():
    # inline="always" re-types and re-lowers the callee at every call site (the IRA search's took ~40 CPU s
    # to compile); forceinline=True lets LLVM inline the compiled callee instead: same bits and speed
    assert _inline_always_uses() == []


def test_the_scanner_sees_inline_always(tmp_path):
    tree = ast.parse('@njit(cache=True, inline="always")\ndef f(x):\n    return x\n')
    kws = [n for n in ast.walk(tree) if isinstance(n, ast.keyword) and n.arg == "inline"]
    assert len(kws) == 1 and kws[0].value.value == "always"


def test_integer_constants_do_not_multiply_specialisations():
    # predict_covariance calls _set_skew with three (row, column) constant pairs: as bare integers they
    # are numba literal types and compiled three specialisations; np.int64(...) makes them one. A fresh,
    # uncached copy of the caller is typed here, so its callee's signatures are filled in even when the
    # cache holds predict_covariance itself.
    from numba import njit
    from trn_env.navigators.filters import _ekf_kernels

    fresh = njit(cache=False)(_ekf_kernels.predict_covariance.py_func)
    P = np.eye(13)
    t = np.arange(1.0, 3.0, 0.5)
    hist = np.zeros((t.shape[0], 10))
    hist[:, 0] = 0.6
    hist[:, 2] = 1000.0
    hist[:, 6] = 1.0
    f_b = np.zeros((t.shape[0], 3))
    fresh(P, np.eye(13) * 1e-6, t, f_b, hist, hist[0].copy(), np.zeros(3), np.zeros(3), 1.0, 0.5, 2, 100.0)
    assert np.isfinite(P).all()
    assert len(_ekf_kernels._set_skew.signatures) == 1, _ekf_kernels._set_skew.signatures


def _prange_index_calls(tree: ast.AST) -> list[int]:
    """Lines where a call inside a `for i in prange(...)` loop takes the bare loop index i as an argument
    (np.int64(i) aside)."""
    hits = []
    for loop in ast.walk(tree):
        if not (isinstance(loop, ast.For) and isinstance(loop.target, ast.Name)
                and isinstance(loop.iter, ast.Call) and getattr(loop.iter.func, "id", None) == "prange"):
            continue
        index = loop.target.id
        for node in (n for stmt in loop.body for n in ast.walk(stmt)):
            if (isinstance(node, ast.Call) and getattr(node.func, "attr", None) != "int64"
                    and any(isinstance(a, ast.Name) and a.id == index for a in node.args)):
                hits.append(node.lineno)
    return hits


def test_parallel_loops_pass_their_index_to_kernels_as_int64():
    # numba types a prange loop's index int64 but lowers the parallel loop with a uint64 index: a kernel
    # called with the bare index compiles twice (with its callees: ~3 s of the fast tier's compile)
    hits = []
    for pkg in ("terrain", "navigators", "trn_env"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            lines = _prange_index_calls(ast.parse(path.read_text()))
            hits += [f"{path.relative_to(ROOT)}:{line}" for line in lines]
    assert hits == []


def test_the_scanner_sees_a_bare_prange_index_in_a_call():
    tree = ast.parse("for i in prange(n):\n    f(np.int64(i), x)\n    g(x, i)\n    y = a[i]\n")
    assert _prange_index_calls(tree) == [3]
