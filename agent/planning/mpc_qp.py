"""The QP the MPC tracker solves (`agent.planning.mpc`): its weights and solver settings,
and its sparse structure, assembled once.

`MpcTuning` holds the weights and OSQP settings (`DEFAULT_TUNING`; the paper profile's
`PAPER_TUNING`; `profile_tuning` picks one of the two for a configuration's profile). The
planner takes its tuning as an input (`agent.planning.planners.make_planner`), so a
tracker with other weights is built, never patched in.

`build_qp` assembles, for a horizon, the robot's limits and a tuning, the constant cost
matrix P, the constraint matrix A at placeholder values, the constant parts of q, l and u,
where each entry that changes every cycle lands, the warm-start shifts and the fixed Ruiz
scaling (`QpLayout`). The formulation (variables z, the cost J, the row blocks of A) and
the names used here are in `agent.planning.mpc`'s docstring.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from agent.core.config import MpcConfig, PlannerConfig, RobotLimits

OSQP_INF = 1.0e30  # OSQP_INFTY: bounds beyond it are infinite


@dataclass(frozen=True)
class MpcTuning:
    """The tracker's weights and solver settings (constants, not user settings).

    Args:
        q_position: weight on squared position error per step [1/m^2]; with `r_v` it
            makes a 0.3 m lag cost about as much as a 1 m/s speed error.
        q_heading: weight on squared heading error per step [1/rad^2].
        q_terminal: multiplier on the last step's state weight (a terminal cost that
            stands in for the rest of the path beyond the horizon).
        r_v: weight on (v - v_ref)^2.
        r_omega: weight on (omega - omega_ref)^2.
        r_dv: weight on squared change of v between steps (smooth commands).
        r_domega: weight on squared change of omega between steps.
        max_constraints: neighbours turned into half-planes (nearest predicted gap first);
            the via-points and the braking guard handle the rest.
        slack_weight: linear and quadratic weight on half-plane slack. The linear part
            makes the penalty exact (no slack while it can be avoided) as long as a step's
            half-plane multipliers sum to less than it; a larger weight dominates the
            residual norms OSQP's rho adaptation balances and lengthens the iteration tail.
        max_iter: OSQP iteration cap per solve, counted in whole chunks.
        settle_chunk_iter: OSQP runs in chunks of this many iterations (rounded up to a
            multiple of 25, the rho adaptation interval; 0: one run to `max_iter`); after
            a chunk short of the tolerances, the solve stops once the first command (the
            only one applied) moved by less than the settle tolerances over it. The slow
            QPs of a crowd spend their last iterations on the far end of the horizon.
        settle_v_tol_mps: see `settle_chunk_iter` [m/s].
        settle_omega_tol_radps: see `settle_chunk_iter` [rad/s].
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
    """

    q_position: float = 10.0
    q_heading: float = 0.5
    q_terminal: float = 2.0
    r_v: float = 1.0
    r_omega: float = 0.2
    r_dv: float = 2.0
    r_domega: float = 0.5
    max_constraints: int = 4
    slack_weight: float = 1.0e3
    max_iter: int = 1000
    settle_chunk_iter: int = 100
    settle_v_tol_mps: float = 0.01
    settle_omega_tol_radps: float = 0.01
    eps_abs: float = 1.0e-3
    eps_rel: float = 1.0e-3


DEFAULT_TUNING = MpcTuning()
"""eIFP-MPC's tracker in the default profile."""

PAPER_TUNING = MpcTuning(q_terminal=1.0, r_dv=0.0, r_domega=0.0)
"""The paper's J (Eq. 21): one state weight Q for every step (no terminal multiplier) and an
input weight R, no input-rate terms. The inputs' rate bounds stay: they are the robot's
actuation limits, which the world enforces too."""


def profile_tuning(config: PlannerConfig) -> MpcTuning:
    """The tuning of `config`'s profile: `PAPER_TUNING` in ``paper``, else `DEFAULT_TUNING`
    (the planners' default when they are given none)."""
    return PAPER_TUNING if config.is_paper else DEFAULT_TUNING


@dataclass(frozen=True)
class QpLayout:
    """The tracker's QP as set up once: matrices, constant vectors and index maps.

    Variables z = [dx_1 .. dx_N (3N) | du_0 .. du_{N-1} (2N) | s_1 .. s_N (N, none without
    neighbour slots)], n in all; rows in blocks by step: dynamics (3N), input bounds (2N),
    input rates (2N), half-planes (N M), slack signs (N, or none), m in all. The scaled
    problem OSQP sees is P~ = c D P D, q~ = c D q, A~ = E A D, l~ = E l, u~ = E u, with
    z = D z~ and y = E y~ / c (`_ruiz`).

    Attributes:
        n_x, n_u: 3N and 2N, the sizes of the dx and du parts of z.
        A: (m, n) constraint matrix at placeholder values (its sparsity pattern is fixed).
        p_scaled: (n, n) upper triangle of P~, constant.
        q, l, u: (n,), (m,), (m,) the constant parts of q, l and u (zero where the tracker
            writes each cycle).
        box_rows, rate_rows: the input-bound and the input-rate rows, 2N each.
        q_state: (N, 3) 2 Q_k; r_w, rd_w: (2,) 2 R and 2 R_d (the weights in q).
        entries: where the entries of A that change each cycle lie in A.data.
        hp_rows: (M, N) slot j's half-plane rows, by step.
        row_shift: (m,) the row whose dual each row's warm start takes (one step on).
        slack_shift: (N,) or (0,) the same for the slacks, indices into s.
        d_var, e_row: (n,), (m,) the scalings D and E.
        a_scale: (nnz,) E_i D_j of each entry of A.data.
        q_scale: (n,) c D.
        y_ws_scale: (m,) E of the row each shifted dual comes from over E of its own row.
        slack_ws_scale: (N,) or (0,) 1 / D of the slacks.
        i_first, d_first: (2,) du_0's indices in z and their D.
    """

    n_x: int
    n_u: int
    A: sp.csc_matrix
    p_scaled: sp.csc_matrix
    q: np.ndarray
    l: np.ndarray
    u: np.ndarray
    box_rows: slice
    rate_rows: slice
    q_state: np.ndarray
    r_w: np.ndarray
    rd_w: np.ndarray
    entries: ChangingEntries
    hp_rows: np.ndarray
    row_shift: np.ndarray
    slack_shift: np.ndarray
    d_var: np.ndarray
    e_row: np.ndarray
    a_scale: np.ndarray
    q_scale: np.ndarray
    y_ws_scale: np.ndarray
    slack_ws_scale: np.ndarray
    i_first: np.ndarray
    d_first: np.ndarray


@dataclass(frozen=True)
class ChangingEntries:
    """Where the entries of A that change each cycle lie in A.data.

    Attributes:
        a02, a12: (N - 1,) A_k's -v sin(th) dt and v cos(th) dt, k = 1..N-1.
        b00, b10: (N,) B_k's cos(th) dt and sin(th) dt.
        hx, hy: (M, N) neighbour slot j's half-plane normal, by step.
    """

    a02: np.ndarray
    a12: np.ndarray
    b00: np.ndarray
    b10: np.ndarray
    hx: np.ndarray
    hy: np.ndarray


@dataclass(frozen=True)
class _Blocks:
    """Where the variables and the row blocks sit, by step k (see `QpLayout`)."""

    ix: np.ndarray  # (N, 3) ix[k - 1] -> dx_k
    iu: np.ndarray  # (N, 2) iu[k] -> du_k
    i_s: np.ndarray  # (N,) or (0,) i_s[k - 1] -> s_k
    r_dyn: np.ndarray  # (N, 3) row of dx_{k+1}, component i
    r_box: np.ndarray  # (N, 2)
    r_rate: np.ndarray  # (N, 2)
    r_hp: np.ndarray  # (N, M)
    r_slack: np.ndarray  # (N,) or (0,)


def build_qp(limits: RobotLimits, config: MpcConfig, tuning: MpcTuning,
             trust_weight: float) -> QpLayout:
    """Assemble the tracker's QP (see the module docstring).

    Args:
        limits: actuation limits (the placeholder speed the scaling is computed on).
        config: horizon N and step dt_s.
        tuning: weights and M = `max_constraints`.
        trust_weight: w_t of the trust-region term [1/(m/s)^2, 1/(rad/s)^2].
    """
    n_steps, n_cons = config.horizon_steps, tuning.max_constraints
    blocks = _blocks(n_steps, n_cons)
    nx, nu, ns = 3 * n_steps, 2 * n_steps, blocks.i_s.size
    n_var, n_rows = nx + nu + ns, 7 * n_steps + blocks.r_hp.size + ns
    P, q_state = _cost_matrix(tuning, trust_weight, blocks, n_var)
    A, entries = _constraint_matrix(limits, config.dt_s, blocks, (n_rows, n_var))
    r_box, r_rate, r_hp = blocks.r_box, blocks.r_rate, blocks.r_hp

    # --- vectors: constant parts written once ----------------------------------------
    q = np.zeros(n_var)
    q[nx + nu :] = tuning.slack_weight
    lo = np.zeros(n_rows)
    hi = np.zeros(n_rows)
    lo[r_hp.ravel()] = -OSQP_INF
    hi[r_hp.ravel()] = OSQP_INF
    lo[7 * n_steps + r_hp.size :] = 0.0
    hi[7 * n_steps + r_hp.size :] = OSQP_INF

    # Dual warm start: row block of step k takes the duals of step k + 1 (last repeated).
    shift = np.minimum(np.arange(n_steps) + 1, n_steps - 1)
    row_shift = np.concatenate(
        [
            blocks.r_dyn[shift].ravel(),
            r_box[shift].ravel(),
            r_rate[shift].ravel(),
            r_hp[shift].ravel(),
            blocks.r_slack[shift].ravel() if ns else blocks.r_slack,
        ]
    )
    i_s = blocks.i_s
    slack_shift = (i_s[shift] - (nx + nu)).ravel() if ns else i_s

    # Fixed diagonal equilibration (Ruiz), computed once on the placeholder values.
    # OSQP's own scaling would redo Ruiz at every matrix update (~4x the cost of the
    # refactorisation), so it is off: OSQP sees P~ = c D P D, q~ = c D q, A~ = E A D,
    # l~ = E l, u~ = E u, and z = D z~, y = E y~ / c.
    d_var, e_row, c_cost = _ruiz(P, A)
    entry_row = A.indices
    entry_col = np.repeat(np.arange(n_var), np.diff(A.indptr))
    p_scaled = P.copy()
    p_scaled.data *= (
        c_cost * d_var[p_scaled.indices] * d_var[np.repeat(np.arange(n_var), np.diff(P.indptr))]
    )
    i_first = np.array([blocks.iu[0, 0], blocks.iu[0, 1]])
    return QpLayout(
        n_x=nx, n_u=nu, A=A, p_scaled=p_scaled, q=q, l=lo, u=hi,
        box_rows=slice(r_box[0, 0], r_box[-1, -1] + 1),
        rate_rows=slice(r_rate[0, 0], r_rate[-1, -1] + 1),
        q_state=q_state,
        r_w=2.0 * np.array([tuning.r_v, tuning.r_omega]),
        rd_w=2.0 * np.array([tuning.r_dv, tuning.r_domega]),
        entries=entries, hp_rows=r_hp.T.copy(),
        row_shift=row_shift, slack_shift=slack_shift,
        d_var=d_var, e_row=e_row,
        a_scale=e_row[entry_row] * d_var[entry_col],
        q_scale=c_cost * d_var,
        y_ws_scale=e_row[row_shift] / e_row,  # scaled duals, shifted
        slack_ws_scale=1.0 / d_var[nx + nu :],
        i_first=i_first, d_first=d_var[i_first],
    )


def _blocks(n_steps: int, n_cons: int) -> _Blocks:
    """The variables' and the row blocks' indices; no slacks without neighbour slots."""
    nx, nu, ns = 3 * n_steps, 2 * n_steps, (n_steps if n_cons else 0)
    k_all = np.arange(n_steps)
    row0 = 3 * n_steps
    r_box = row0 + 2 * k_all[:, None] + np.arange(2)
    row0 += 2 * n_steps
    r_rate = row0 + 2 * k_all[:, None] + np.arange(2)
    row0 += 2 * n_steps
    r_hp = row0 + n_cons * k_all[:, None] + np.arange(n_cons)  # (N, M)
    row0 += n_steps * n_cons
    return _Blocks(
        ix=np.arange(nx).reshape(n_steps, 3),
        iu=nx + np.arange(nu).reshape(n_steps, 2),
        i_s=nx + nu + np.arange(ns),
        r_dyn=3 * k_all[:, None] + np.arange(3),
        r_box=r_box,
        r_rate=r_rate,
        r_hp=r_hp,
        r_slack=row0 + np.arange(ns),
    )


def _cost_matrix(tuning: MpcTuning, trust_weight: float, blocks: _Blocks,
                 n_var: int) -> tuple[sp.csc_matrix, np.ndarray]:
    """P's upper triangle (constant: twice the weights of J) and 2 Q_k, (N, 3)."""
    ix, iu, i_s = blocks.ix, blocks.iu, blocks.i_s
    n_steps, ns = ix.shape[0], i_s.size
    q_diag = np.tile([tuning.q_position, tuning.q_position, tuning.q_heading], (n_steps, 1))
    q_diag[-1] *= tuning.q_terminal
    r_w = np.array([tuning.r_v, tuning.r_omega])
    rd_w = np.array([tuning.r_dv, tuning.r_domega])
    # D'R_dD of the difference operator: 2 r_d on the diagonal (r_d at k = N-1), -r_d off.
    u_diag = np.tile(r_w, (n_steps, 1)) + np.tile(rd_w, (n_steps, 1)) * 2.0
    u_diag[-1] -= rd_w
    u_diag += trust_weight  # ||du||^2: damps the one-linearisation-per-cycle iteration
    p_rows = np.concatenate([ix.ravel(), iu.ravel(), i_s.ravel(), iu[:-1].ravel()])
    p_cols = np.concatenate([ix.ravel(), iu.ravel(), i_s.ravel(), iu[1:].ravel()])
    p_vals = 2.0 * np.concatenate(
        [
            q_diag.ravel(),
            u_diag.ravel(),
            np.full(ns, tuning.slack_weight),
            -np.tile(rd_w, n_steps - 1),
        ]
    )
    P, _ = _csc(p_rows, p_cols, p_vals, (n_var, n_var))
    return P, 2.0 * q_diag


def _constraint_matrix(limits: RobotLimits, dt: float, blocks: _Blocks,
                       shape: tuple[int, int]) -> tuple[sp.csc_matrix, ChangingEntries]:
    """A, row blocks ordered by k, at placeholder values, and where its changing entries lie."""
    ix, iu, i_s = blocks.ix, blocks.iu, blocks.i_s
    r_dyn, r_hp = blocks.r_dyn, blocks.r_hp
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    n_entries = 0

    def add(r: np.ndarray, c: np.ndarray, v: float | np.ndarray) -> np.ndarray:
        nonlocal n_entries
        r, c = np.broadcast_arrays(np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64))
        rows.append(r.ravel())
        cols.append(c.ravel())
        vals.append(np.broadcast_to(np.asarray(v, dtype=float), r.shape).ravel())
        ids = n_entries + np.arange(r.size).reshape(r.shape)
        n_entries += r.size
        return ids

    # Placeholder values of typical magnitude: the equilibration is computed on them.
    v0, th0 = 0.5 * (limits.v_max_mps + limits.v_min_mps), 0.25 * np.pi
    add(r_dyn, ix, -1.0)
    add(r_dyn[1:], ix[:-1], 1.0)  # A_k diagonal, k >= 1
    a02 = add(r_dyn[1:, 0], ix[:-1, 2], -v0 * np.sin(th0) * dt)
    a12 = add(r_dyn[1:, 1], ix[:-1, 2], v0 * np.cos(th0) * dt)
    b00 = add(r_dyn[:, 0], iu[:, 0], np.cos(th0) * dt)
    b10 = add(r_dyn[:, 1], iu[:, 0], np.sin(th0) * dt)
    add(r_dyn[:, 2], iu[:, 1], dt)
    add(blocks.r_box, iu, 1.0)
    add(blocks.r_rate, iu, 1.0)
    add(blocks.r_rate[1:], iu[:-1], -1.0)
    hx = add(r_hp, np.broadcast_to(ix[:, 0:1], r_hp.shape), np.sqrt(0.5))
    hy = add(r_hp, np.broadcast_to(ix[:, 1:2], r_hp.shape), np.sqrt(0.5))
    if i_s.size:  # without neighbour slots there are no half-planes and no slack
        add(r_hp, np.broadcast_to(i_s[:, None], r_hp.shape), 1.0)
    add(blocks.r_slack, i_s, 1.0)
    A, position = _csc(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), shape)
    # (M, N): row j holds neighbour slot j's entries over the horizon.
    return A, ChangingEntries(a02=position[a02], a12=position[a12], b00=position[b00],
                              b10=position[b10], hx=position[hx].T.copy(),
                              hy=position[hy].T.copy())


def _csc(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int]
         ) -> tuple[sp.csc_matrix, np.ndarray]:
    """CSC matrix of COO triplets (no duplicates) and where each triplet lands in `.data`."""
    order = np.lexsort((rows, cols))  # column-major, rows sorted within a column
    r, c = rows[order], cols[order]
    if np.any((np.diff(c) == 0) & (np.diff(r) == 0)):
        raise ValueError("duplicate entries")
    indptr = np.zeros(shape[1] + 1, dtype=np.int64)
    np.cumsum(np.bincount(c, minlength=shape[1]), out=indptr[1:])
    position = np.empty_like(order)
    position[order] = np.arange(order.shape[0])
    matrix = sp.csc_matrix((vals[order].astype(float), r, indptr), shape=shape)
    return matrix, position


def _ruiz(P: sp.csc_matrix, A: sp.csc_matrix, iterations: int = 10
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """Ruiz equilibration of the KKT matrix [[P, A'], [A, 0]], as OSQP's `scaling` does.

    The cost scaling c uses P only (OSQP also uses q, which here changes every cycle).
    Works on the nonzeros of P and A directly (numpy, no sparse matrix products: about
    70 ms less per tracker set up, i.e. per robot start); each scaled entry is computed as
    (d_i x_ij) d_j, in the order of the sparse products diag(d) X diag(d) it replaces, so
    the scaling is bit for bit the same (tests/unit/agent/planning/test_mpc_qp.py).

    Args:
        P: (n, n) upper triangle of the cost matrix; A: (m, n) constraint matrix.

    Returns:
        d: (n,) variable scaling, e: (m,) row scaling, c: cost scaling.
    """
    p_full = (P + sp.triu(P, 1).T).tocsc()
    a = A.tocsc()
    n, m = P.shape[0], A.shape[0]
    p_abs, p_row, p_col = _entries(p_full)
    a_abs, a_row, a_col = _entries(a)
    d = np.ones(n)
    e = np.ones(m)
    for _ in range(iterations):
        col = np.maximum(_max_at(p_abs, p_col, n), _max_at(a_abs, a_col, n))
        row = _max_at(a_abs, a_row, m)
        d_step = 1.0 / np.sqrt(np.clip(col, 1e-4, 1e4))
        e_step = 1.0 / np.sqrt(np.clip(row, 1e-4, 1e4))
        d *= d_step
        e *= e_step
        p_abs = (d_step[p_row] * p_abs) * d_step[p_col]
        a_abs = (e_step[a_row] * a_abs) * d_step[a_col]
    c = 1.0 / float(np.clip(np.mean(_max_at(p_abs, p_col, n)), 1e-4, 1e4))
    return d, e, c


def _entries(matrix: sp.csc_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|values|, rows and columns of a CSC matrix's stored entries."""
    cols = np.repeat(np.arange(matrix.shape[1]), np.diff(matrix.indptr))
    return np.abs(matrix.data), matrix.indices.astype(np.int64), cols


def _max_at(values: np.ndarray, index: np.ndarray, size: int) -> np.ndarray:
    """The largest of `values` per index (0 where an index has none; values >= 0)."""
    out = np.zeros(size)
    np.maximum.at(out, index, values)
    return out
