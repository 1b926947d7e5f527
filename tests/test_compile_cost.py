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
