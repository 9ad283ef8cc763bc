"""The tracker QP's fixed Ruiz scaling: the same bits as the sparse-product form it
replaced, and an equilibrated KKT matrix."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import MpcConfig, RobotLimits
from agent.planning import mpc_qp
from agent.planning.mpc_qp import DEFAULT_TUNING, PAPER_TUNING, build_qp


def reference_ruiz(P: sp.csc_matrix, A: sp.csc_matrix, iterations: int = 10
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Ruiz equilibration with scipy's sparse products, as the tracker computed it before."""
    p_full = (P + sp.triu(P, 1).T).tocsc()
    a = A.tocsc()
    d = np.ones(P.shape[0])
    e = np.ones(A.shape[0])
    for _ in range(iterations):
        col = np.maximum(abs(p_full).max(axis=0).toarray().ravel(),
                         abs(a).max(axis=0).toarray().ravel())
        row = abs(a).max(axis=1).toarray().ravel()
        d_step = 1.0 / np.sqrt(np.clip(col, 1e-4, 1e4))
        e_step = 1.0 / np.sqrt(np.clip(row, 1e-4, 1e4))
        d *= d_step
        e *= e_step
        p_full = sp.diags(d_step) @ p_full @ sp.diags(d_step)
        a = sp.diags(e_step) @ a @ sp.diags(d_step)
    c = 1.0 / float(np.clip(np.mean(abs(p_full).max(axis=0).toarray()), 1e-4, 1e4))
    return d, e, c


def tracker_matrices(monkeypatch: pytest.MonkeyPatch, tuning: mpc_qp.MpcTuning, steps: int
                     ) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """The (P, A) that `build_qp` scales, for one tuning and horizon."""
    seen: list[tuple[sp.csc_matrix, sp.csc_matrix]] = []
    real = mpc_qp._ruiz

    def spy(P: sp.csc_matrix, A: sp.csc_matrix, iterations: int = 10
            ) -> tuple[np.ndarray, np.ndarray, float]:
        seen.append((P.copy(), A.copy()))
        return real(P, A, iterations)

    monkeypatch.setattr(mpc_qp, "_ruiz", spy)
    build_qp(RobotLimits(), MpcConfig(horizon_steps=steps), tuning, 0.1)
    assert len(seen) == 1
    return seen[0]


@pytest.mark.parametrize("tuning", [DEFAULT_TUNING, PAPER_TUNING], ids=["default", "paper"])
@pytest.mark.parametrize("steps", [1, 5, 20])
def test_the_tracker_scaling_is_bit_for_bit_the_sparse_product_form(monkeypatch, tuning, steps):
    P, A = tracker_matrices(monkeypatch, tuning, steps)
    d, e, c = mpc_qp._ruiz(P, A)
    d_ref, e_ref, c_ref = reference_ruiz(P, A)
    assert np.array_equal(d, d_ref)
    assert np.array_equal(e, e_ref)
    assert c == c_ref


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12), m=st.integers(1, 15),
       density=st.floats(0.05, 0.9))
def test_random_matrices_scale_as_the_sparse_product_form(seed, n, m, density):
    rng = np.random.default_rng(seed)
    # Entries over eight decades, some columns and rows empty.
    def rand(rows: int, cols: int) -> sp.csc_matrix:
        dense = rng.normal(size=(rows, cols)) * 10.0 ** rng.uniform(-4, 4, size=(rows, cols))
        dense[rng.random((rows, cols)) > density] = 0.0
        return sp.csc_matrix(dense)
    P = sp.csc_matrix(sp.triu(rand(n, n)))
    A = rand(m, n)
    d, e, c = mpc_qp._ruiz(P, A)
    d_ref, e_ref, c_ref = reference_ruiz(P, A)
    assert np.array_equal(d, d_ref)
    assert np.array_equal(e, e_ref)
    assert c == c_ref


def test_the_scaled_kkt_matrix_is_equilibrated(monkeypatch):
    # Ruiz drives every column and row of [[P, A'], [A, 0]] to an infinity norm near 1.
    P, A = tracker_matrices(monkeypatch, DEFAULT_TUNING, 20)
    d, e, _ = mpc_qp._ruiz(P, A)
    p_full = (P + sp.triu(P, 1).T).toarray()
    scaled_p = d[:, None] * p_full * d[None, :]
    scaled_a = e[:, None] * A.toarray() * d[None, :]
    col = np.maximum(np.abs(scaled_p).max(axis=0), np.abs(scaled_a).max(axis=0))
    row = np.abs(scaled_a).max(axis=1)
    used_rows = np.abs(A.toarray()).max(axis=1) > 0.0
    assert np.all((col > 0.5) & (col < 2.0))
    assert np.all((row[used_rows] > 0.5) & (row[used_rows] < 2.0))
