"""LTV-MPC tracker of eIFP-MPC on the discrete unicycle (Eq. 1), solved with OSQP.

Formulation ("Trajectory Smoothing and MPC Tracking": the unicycle of Eq. 20, which is
Eq. 1, the cost J of Eq. 21 and the input bounds of Eq. 22). Each cycle
the unicycle is linearised about a nominal trajectory (xb_k, ub_k): the previous optimal
inputs shifted by one step (the last one repeated), or the reference inputs on the first
cycle, rolled out through Eq. (1) from the measured state x_0. The QP variables are the
*deviations* from that nominal,

    z = [dx_1 .. dx_N (3N) | du_0 .. du_{N-1} (2N) | s_k, k = 1..N (N)],

with x_k = xb_k + dx_k, u_k = ub_k + du_k and dx_0 = 0 (the nominal starts at x_0). The
dynamics are dx_{k+1} = A_k dx_k + B_k du_k (A_k, B_k: `unicycle.jacobians` at xb_k, ub_k),
exact to first order and with zero residual, because the nominal is a rollout of Eq. (1).
Deviation form keeps every variable small (well scaled for OSQP), makes the primal
warm start of the shifted solution simply z = 0, and avoids heading wrap: heading errors
are wrap(thb_k - th_ref_k), i.e. the reference heading unwrapped near the nominal.

Cost (OSQP minimises 1/2 z'Pz + q'z; P holds twice the weights below):

    J = sum_{k=1..N} ||x_k - x_ref_k||^2_{Q_k}           Q_k = diag(q_pos, q_pos, q_head),
                                                            times q_terminal at k = N
      + sum_{k=0..N-1} ||u_k - u_ref_k||^2_R              R = diag(r_v, r_omega)
      + sum_{k=0..N-1} ||u_k - u_{k-1}||^2_{R_d}         R_d = diag(r_dv, r_domega),
                                                            u_{-1} = last applied command
      + w_s sum_k (s_k + s_k^2)                           w_s = slack_weight
      + w_t sum_{k=0..N-1} ||u_k - ub_k||^2               trust region about the nominal

The trust-region term is not in the paper's J. One linearisation per cycle is one
Gauss-Newton step of the nonlinear MPC (real-time iteration); the model is linear in the
heading, so with a large position error the QP over-rotates (cos is not linear) and the
closed loop wobbles. The term damps the step; it vanishes at the fixed point where the
plan stops changing between cycles (u = ub), so it does not bias a converged plan.
All weights are constant, so P never changes: only q moves with the nominal and reference.

Constraints l <= A z <= u, in row blocks ordered by step k:
  * dynamics (3N rows, = 0): -dx_{k+1} + A_k dx_k + B_k du_k = 0;
  * input bounds (2N rows): v_min <= v_k <= v_max, |omega_k| <= omega_max;
  * input rates (2N rows): |v_k - v_{k-1}| <= accel_max dt, |omega_k - omega_{k-1}| <=
    alpha_max dt, with u_{-1} the last applied command;
  * neighbour half-planes (N M rows): n_jk . p_k + s_k >= n_jk . o_jk + c_j, where o_jk
    is neighbour j's predicted centre at step k, c_j its required clearance
    (r_robot + r_j + d_safety) and n_jk the unit vector from o_jk to the nominal position
    pb_k. Up to M = max_constraints neighbours, smallest predicted gap first; unused rows
    get zero coefficients and infinite bounds, so the sparsity pattern never changes;
  * slack signs (N rows): s_k >= 0.
The slack makes the QP always feasible; the half-plane is the tangent of the clearance
disc, so n . p >= n . o + c implies |p - o| >= c exactly. One slack per step, shared by
that step's M half-planes, so s_k is the step's largest violation and the penalty is
exact while the step's multipliers sum to less than w_s (a robot facing a gap narrower
than the clearances stops in front of it: tests/unit/agent/planning/test_mpc.py). A slack
per (step, neighbour) would add N M variables and sign rows (180 variables and 300 rows
against 120 and 240 at N = 20, M = 4) for a larger KKT system to factor every cycle.

The QP is set up once; each cycle writes the changing entries of A (B_k, the v-dependent
column of A_k, the half-plane normals) through precomputed indices into A's CSC data, and
q, l, u; OSQP is warm-started with the shifted solution (z = 0 primal, duals shifted by
one step). Every call goes through osqp's public API (`osqp.OSQP`: setup, update,
warm_start, solve); its `update` clamps bounds beyond OSQP_INFTY to infinity. The problem
is equilibrated once, at setup, by a fixed diagonal (Ruiz) scaling, and OSQP's own scaling
is off: it would redo Ruiz at every matrix update, which cost about four times the KKT
refactorisation itself. The command period is taken equal
to dt (the rate bounds use it).

The weights and solver settings are `MpcTuning` constants (`DEFAULT_TUNING`; the paper
profile's `PAPER_TUNING`), the horizon and the half-planes' margin `MpcConfig` settings.

OSQP runs in chunks of `MpcTuning.settle_chunk_iter` iterations (rounded up to a multiple
of the rho adaptation interval), each going on from OSQP's own iterates, so a chunked solve
is the same ADMM run as one call; between chunks the solve stops once the first command
(the only one applied) has settled (moved less than `settle_v_tol_mps` /
`settle_omega_tol_radps` over a chunk), else at `max_iter` in all.

Outcome: OSQP solved -> OK. Iteration cap, a settled first command (or inaccurate) with a
finite iterate -> SOLVER_INACCURATE, the iterate is used. Anything else (infeasible,
non-convex, NaN, an exception) -> SOLVER_FAILED: brake, i.e. v falls at accel_max and
omega decays to 0 at alpha_max (both rate limits kept), `failures` += 1 and the warm start
is dropped. The command is always clipped to the bounds and to the rate limits from the
last command.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import osqp
import scipy.sparse as sp

from agent.core.config import MpcConfig, RobotLimits
from agent.core.types import PlanStatus
from agent.planning.unicycle import clamp_command, rollout, rollout_with_trig

_INF = 1.0e30  # OSQP_INFTY: bounds beyond it are infinite
_RHO_INTERVAL = 25  # OSQP iterations between rho adaptations
_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)
_USABLE = frozenset(
    int(s)
    for s in (
        osqp.SolverStatus.OSQP_SOLVED_INACCURATE,
        osqp.SolverStatus.OSQP_MAX_ITER_REACHED,
        osqp.SolverStatus.OSQP_TIME_LIMIT_REACHED,
    )
)


class ReferenceLike(Protocol):
    """What the tracker reads of `agent.planning.spline.Reference`: (N + 1,) samples at t = k dt."""

    @property
    def x_m(self) -> np.ndarray: ...

    @property
    def y_m(self) -> np.ndarray: ...

    @property
    def heading_rad(self) -> np.ndarray: ...

    @property
    def v_mps(self) -> np.ndarray: ...

    @property
    def omega_radps(self) -> np.ndarray: ...


@dataclass(frozen=True)
class MpcResult:
    """Outcome of one MPC cycle.

    Args:
        v_mps, omega_radps: command to apply now, always within the bounds and rate limits.
        status: OK, SOLVER_INACCURATE (iterate used, clipped) or SOLVER_FAILED (braking).
        iterations: OSQP iterations (0 when OSQP was not called).
        planned_inputs: (N, 2) the planned [v_mps, omega_radps] per step, the first applied.
        initial_state: (3,) the state the plan starts from.
        dt_s: step length of the plan.
        max_slack_m: largest half-plane violation the plan accepts (0 when feasible).
    """

    v_mps: float
    omega_radps: float
    status: PlanStatus
    iterations: int
    planned_inputs: np.ndarray
    initial_state: np.ndarray
    dt_s: float
    max_slack_m: float

    @functools.cached_property
    def predicted_states(self) -> np.ndarray:
        """(N + 1, 3) Eq. (1) rollout of the planned inputs from the state.

        Computed on first use (`PlanDebug.predicted_m` uses it: one vectorised rollout).
        """
        return rollout(self.initial_state, self.planned_inputs, self.dt_s)


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

    Args:
        P: (n, n) upper triangle of the cost matrix; A: (m, n) constraint matrix.

    Returns:
        d: (n,) variable scaling, e: (m,) row scaling, c: cost scaling.
    """
    p_full = (P + sp.triu(P, 1).T).tocsc()
    a = A.tocsc()
    d = np.ones(P.shape[0])
    e = np.ones(A.shape[0])
    for _ in range(iterations):
        col = np.maximum(
            abs(p_full).max(axis=0).toarray().ravel(), abs(a).max(axis=0).toarray().ravel()
        )
        row = abs(a).max(axis=1).toarray().ravel()
        d_step = 1.0 / np.sqrt(np.clip(col, 1e-4, 1e4))
        e_step = 1.0 / np.sqrt(np.clip(row, 1e-4, 1e4))
        d *= d_step
        e *= e_step
        p_full = sp.diags(d_step) @ p_full @ sp.diags(d_step)
        a = sp.diags(e_step) @ a @ sp.diags(d_step)
    c = 1.0 / float(np.clip(np.mean(abs(p_full).max(axis=0).toarray()), 1e-4, 1e4))
    return d, e, c


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


class MpcTracker:
    """LTV-MPC reference tracker with soft neighbour half-planes (see the module docstring).

    Args:
        limits: actuation limits (bounds and rate limits of the inputs).
        config: horizon and step (the half-planes' margin is the caller's).
        tuning: weights, constraint cap and OSQP settings.
        trust_weight: weight w_t of the trust-region term w_t ||u_k - ub_k||^2
            [1/(m/s)^2, 1/(rad/s)^2] (see the module docstring).
        solver_factory: makes the QP solver, called once; the tracker uses osqp's public
            API only (`setup`, `update`, `warm_start`, `solve`), so a subclass of
            `osqp.OSQP` can stand in for it (the tests' way to make OSQP fail).

    Attributes:
        failures: number of cycles that ended in SOLVER_FAILED since construction.
    """

    def __init__(self, limits: RobotLimits, config: MpcConfig,
                 tuning: MpcTuning = DEFAULT_TUNING, trust_weight: float = 1.0,
                 solver_factory: Callable[[], osqp.OSQP] = osqp.OSQP) -> None:
        if trust_weight < 0.0:
            raise ValueError("trust_weight must be non-negative")
        if config.horizon_steps < 1 or config.dt_s <= 0.0 or tuning.max_constraints < 0:
            raise ValueError("MpcConfig: horizon_steps >= 1, dt_s > 0, max_constraints >= 0")
        self.limits = limits
        self.config = config
        self.tuning = tuning
        self.failures = 0
        n_steps, n_cons = config.horizon_steps, tuning.max_constraints
        self._n_steps, self._n_cons = n_steps, n_cons
        dt = config.dt_s
        self._u_min = np.array([limits.v_min_mps, -limits.omega_max_radps])
        self._u_max = np.array([limits.v_max_mps, limits.omega_max_radps])
        self._du_max = np.array([limits.accel_max_mps2 * dt, limits.alpha_max_radps2 * dt])

        nx, nu, ns = 3 * n_steps, 2 * n_steps, (n_steps if n_cons else 0)
        n_hp = n_steps * n_cons
        self._nx, self._nu, self._ns = nx, nu, ns
        n_var = nx + nu + ns
        ix = np.arange(nx).reshape(n_steps, 3)  # ix[k - 1] -> dx_k
        iu = nx + np.arange(nu).reshape(n_steps, 2)  # iu[k] -> du_k
        i_s = nx + nu + np.arange(ns)  # i_s[k - 1] -> s_k

        # --- P (upper triangle), constant --------------------------------------------
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
        self._q_state = 2.0 * q_diag  # (N, 3)
        self._r_w, self._rd_w = 2.0 * r_w, 2.0 * rd_w

        # --- A: row blocks ordered by k; remember every changing entry --------------------
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

        k_all = np.arange(n_steps)
        # Placeholder values of typical magnitude: the equilibration below is computed on them.
        v0, th0 = 0.5 * (limits.v_max_mps + limits.v_min_mps), 0.25 * np.pi
        r_dyn = 3 * k_all[:, None] + np.arange(3)  # (N, 3) row of dx_{k+1}, component i
        add(r_dyn, ix, -1.0)
        add(r_dyn[1:], ix[:-1], 1.0)  # A_k diagonal, k >= 1
        self._a02 = add(r_dyn[1:, 0], ix[:-1, 2], -v0 * np.sin(th0) * dt)
        self._a12 = add(r_dyn[1:, 1], ix[:-1, 2], v0 * np.cos(th0) * dt)
        self._b00 = add(r_dyn[:, 0], iu[:, 0], np.cos(th0) * dt)
        self._b10 = add(r_dyn[:, 1], iu[:, 0], np.sin(th0) * dt)
        add(r_dyn[:, 2], iu[:, 1], dt)
        row0 = 3 * n_steps
        r_box = row0 + 2 * k_all[:, None] + np.arange(2)
        add(r_box, iu, 1.0)
        row0 += 2 * n_steps
        r_rate = row0 + 2 * k_all[:, None] + np.arange(2)
        add(r_rate, iu, 1.0)
        add(r_rate[1:], iu[:-1], -1.0)
        row0 += 2 * n_steps
        r_hp = row0 + n_cons * k_all[:, None] + np.arange(n_cons)  # (N, M)
        self._hx = add(r_hp, np.broadcast_to(ix[:, 0:1], r_hp.shape), np.sqrt(0.5))
        self._hy = add(r_hp, np.broadcast_to(ix[:, 1:2], r_hp.shape), np.sqrt(0.5))
        if n_cons:  # without neighbour slots there are no half-planes and no slack
            add(r_hp, np.broadcast_to(i_s[:, None], r_hp.shape), 1.0)
        row0 += n_hp
        r_slack = row0 + np.arange(ns)
        add(r_slack, i_s, 1.0)
        n_rows = row0 + ns
        A, position = _csc(
            np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), (n_rows, n_var)
        )
        self._a02, self._a12 = position[self._a02], position[self._a12]
        self._b00, self._b10 = position[self._b00], position[self._b10]
        # (M, N): row j holds neighbour slot j's entries over the horizon.
        self._hx, self._hy = position[self._hx].T.copy(), position[self._hy].T.copy()
        self._hp_rows = r_hp.T.copy()
        self._hp_active = n_cons  # slots whose rows may hold a constraint (all, at setup)
        self._a_data = A.data.copy()

        # --- vectors: constant parts written once ----------------------------------------
        self._q = np.zeros(n_var)
        self._q[nx + nu :] = tuning.slack_weight
        self._l = np.zeros(n_rows)
        self._u = np.zeros(n_rows)
        # Views written in place each cycle.
        self._q_x = self._q[:nx].reshape(n_steps, 3)
        self._q_u = self._q[nx : nx + nu].reshape(n_steps, 2)
        self._l_box = self._l[r_box[0, 0] : r_box[-1, -1] + 1].reshape(n_steps, 2)
        self._u_box = self._u[r_box[0, 0] : r_box[-1, -1] + 1].reshape(n_steps, 2)
        self._l_rate = self._l[r_rate[0, 0] : r_rate[-1, -1] + 1].reshape(n_steps, 2)
        self._u_rate = self._u[r_rate[0, 0] : r_rate[-1, -1] + 1].reshape(n_steps, 2)
        self._l[r_hp.ravel()] = -_INF
        self._u[r_hp.ravel()] = _INF
        self._l[7 * n_steps + n_hp :] = 0.0
        self._u[7 * n_steps + n_hp :] = _INF

        # Dual warm start: row block of step k takes the duals of step k + 1 (last repeated).
        shift = np.minimum(k_all + 1, n_steps - 1)
        self._row_shift = np.concatenate(
            [
                r_dyn[shift].ravel(),
                r_box[shift].ravel(),
                r_rate[shift].ravel(),
                r_hp[shift].ravel(),
                r_slack[shift].ravel() if ns else r_slack,
            ]
        )
        self._slack_shift = (i_s[shift] - (nx + nu)).ravel() if ns else i_s
        self._x_zero = np.zeros(n_var)
        self._y_zero = np.zeros(n_rows)

        # Fixed diagonal equilibration (Ruiz), computed once on the placeholder values.
        # OSQP's own scaling would redo Ruiz at every matrix update (~4x the cost of the
        # refactorisation), so it is off: OSQP sees P~ = c D P D, q~ = c D q, A~ = E A D,
        # l~ = E l, u~ = E u, and z = D z~, y = E y~ / c.
        d_var, e_row, c_cost = _ruiz(P, A)
        self._d_var, self._e_row = d_var, e_row
        entry_row = A.indices
        entry_col = np.repeat(np.arange(n_var), np.diff(A.indptr))
        self._a_scale = e_row[entry_row] * d_var[entry_col]
        self._y_ws_scale = e_row[self._row_shift] / e_row  # scaled duals, shifted
        self._slack_ws_scale = 1.0 / d_var[nx + nu :]
        self._q_scale = c_cost * d_var
        p_scaled = P.copy()
        p_scaled.data *= (
            c_cost * d_var[p_scaled.indices] * d_var[np.repeat(np.arange(n_var), np.diff(P.indptr))]
        )
        # Chunks are whole multiples of the rho adaptation interval, so that a chunked
        # solve is the same ADMM run as one call (the adaptation counts from each call).
        chunk = -(-tuning.settle_chunk_iter // _RHO_INTERVAL) * _RHO_INTERVAL
        self._chunk_iter = min(chunk, tuning.max_iter) if chunk > 0 else tuning.max_iter
        i_first = np.array([iu[0, 0], iu[0, 1]])
        self._i_first, self._d_first = i_first, d_var[i_first]
        self._solver = solver_factory()
        self._solver.setup(
            p_scaled,
            self._q * self._q_scale,
            sp.csc_matrix((A.data * self._a_scale, A.indices, A.indptr), shape=A.shape),
            self._l * e_row,
            self._u * e_row,
            verbose=False,
            warm_starting=True,
            polishing=False,
            scaling=0,
            max_iter=self._chunk_iter,
            eps_abs=tuning.eps_abs,
            eps_rel=tuning.eps_rel,
            check_termination=5,
            # Iteration-based rho adaptation (deterministic, unlike the time-based one).
            # A tolerance of 2 rather than 5 re-tunes rho sooner, which the degenerate QP
            # of a robot held in front of a neighbour (all half-planes active and
            # parallel) needs to converge in few iterations.
            adaptive_rho=1,
            adaptive_rho_interval=_RHO_INTERVAL,
            adaptive_rho_tolerance=2.0,
        )
        self._u_prev: np.ndarray | None = None  # (N, 2) last optimal inputs
        self._y_prev: np.ndarray | None = None
        self._s_prev: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the warm start (the next cycle linearises about the reference inputs).

        The `failures` counter is a statistic, not memory, and is kept.
        """
        self._u_prev = None
        self._y_prev = None
        self._s_prev = None

    def solve(
        self,
        state: np.ndarray,
        last_command: np.ndarray,
        reference: ReferenceLike,
        neighbours_pred_m: np.ndarray | None = None,
        clearance_m: np.ndarray | None = None,
    ) -> MpcResult:
        """One MPC cycle: linearise, update the QP in place, solve warm-started, unpack.

        Args:
            state: (3,) measured [x_m, y_m, theta_rad].
            last_command: (2,) applied [v_mps, omega_radps] (u_{-1}; clipped to the bounds).
            reference: (N + 1,) samples at t = k dt, k = 0..N (see `ReferenceLike`).
            neighbours_pred_m: (K, N + 1, 2) neighbours' predicted centres at t = k dt.
            clearance_m: (K,) required centre distance per neighbour (r + r_j + d_safety).

        Returns:
            The command for this cycle; SOLVER_FAILED brakes and increments `failures`.

        Raises:
            ValueError: on wrong shapes or non-finite inputs.
        """
        n_steps, dt = self._n_steps, self.config.dt_s
        x0, last, ref, preds, clear = self._check(
            state, last_command, reference, neighbours_pred_m, clearance_m
        )
        u_min, u_max = self._u_min, self._u_max
        np.minimum(np.maximum(last, u_min, out=last), u_max, out=last)

        # Nominal inputs: the previous solution shifted by one step, else the reference's.
        ub = np.empty((n_steps, 2))
        if self._u_prev is None:
            ub[:, 0] = ref[3, :n_steps]
            ub[:, 1] = ref[4, :n_steps]
        else:
            ub[:-1] = self._u_prev[1:]
            ub[-1] = self._u_prev[-1]
        np.minimum(np.maximum(ub, u_min, out=ub), u_max, out=ub)
        xb, cos_b, sin_b = rollout_with_trig(x0, ub, dt)

        # A: B_k and the v-dependent column of A_k (unicycle.jacobians, entry by entry).
        a = self._a_data
        cos_dt = cos_b * dt
        sin_dt = sin_b * dt
        a[self._b00] = cos_dt
        a[self._b10] = sin_dt
        a[self._a02] = -ub[1:, 0] * sin_dt[1:]
        a[self._a12] = ub[1:, 0] * cos_dt[1:]

        # q: state error (heading wrapped), input error and input change against u_{-1}.
        err = xb[1:] - ref[0:3, 1:].T
        err[:, 2] = np.mod(err[:, 2] + np.pi, 2.0 * np.pi) - np.pi
        np.multiply(self._q_state, err, out=self._q_x)
        g = np.empty((n_steps, 2))  # D ub - e_0 u_{-1}
        np.subtract(ub[0], last, out=g[0])
        np.subtract(ub[1:], ub[:-1], out=g[1:])
        dtg = g.copy()  # D' g
        dtg[:-1] -= g[1:]
        dtg *= self._rd_w
        np.multiply(self._r_w, ub - ref[3:5, :n_steps].T, out=self._q_u)
        self._q_u += dtg
        # l, u: input bounds and rates, relative to the nominal.
        np.subtract(u_min, ub, out=self._l_box)
        np.subtract(u_max, ub, out=self._u_box)
        np.subtract(-self._du_max, g, out=self._l_rate)
        np.subtract(self._du_max, g, out=self._u_rate)
        n_used = self._set_half_planes(xb, preds, clear)

        # Inputs are finite, so only an overflow can make q or l non-finite (a is bounded).
        q, lo, hi = self._q, self._l, self._u
        if not math.isfinite(float(q.sum()) + float(lo.sum())):
            return self._fail(x0, last, 0)
        e_row, n_xu = self._e_row, self._nx + self._nu
        if self._y_prev is None or self._s_prev is None:  # both or neither
            x_ws, y_ws = self._x_zero, self._y_zero
        else:
            # Shifted solution: z = 0 is the nominal; slacks and duals move one step.
            x_ws = self._x_zero.copy()
            x_ws[n_xu:] = self._s_prev[self._slack_shift] * self._slack_ws_scale
            y_ws = self._y_prev[self._row_shift] * self._y_ws_scale
        try:
            status_val, iterations, z_scaled, y_scaled = self._osqp(
                q * self._q_scale, lo * e_row, hi * e_row, a * self._a_scale, x_ws, y_ws
            )
        except (osqp.OSQPException, ValueError):
            return self._fail(x0, last, 0)
        usable = (
            z_scaled is not None
            and y_scaled is not None
            and math.isfinite(float(z_scaled.sum()) + float(y_scaled.sum()))
        )
        if status_val == _SOLVED and usable:
            status = PlanStatus.OK
        elif status_val in _USABLE and usable:
            status = PlanStatus.SOLVER_INACCURATE
        else:
            return self._fail(x0, last, iterations)
        z = z_scaled * self._d_var

        u_opt = ub + z[self._nx : self._nx + self._nu].reshape(n_steps, 2)
        np.minimum(np.maximum(u_opt, u_min, out=u_opt), u_max, out=u_opt)
        v, omega = clamp_command(u_opt[0, 0], u_opt[0, 1], self.limits, last[0], last[1], dt)
        u_opt[0] = v, omega
        slack = z[n_xu:]
        max_slack = 0.0
        if n_used:
            max_slack = max(0.0, float(slack.max()))
        self._u_prev = u_opt
        self._y_prev = y_scaled
        self._s_prev = np.maximum(slack, 0.0)
        return MpcResult(
            v_mps=v,
            omega_radps=omega,
            status=status,
            iterations=iterations,
            planned_inputs=u_opt,
            initial_state=x0,
            dt_s=dt,
            max_slack_m=max_slack,
        )

    def _osqp(
        self,
        q: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        a_data: np.ndarray,
        x_ws: np.ndarray,
        y_ws: np.ndarray,
    ) -> tuple[int, int, np.ndarray | None, np.ndarray | None]:
        """The only place that talks to OSQP: update the scaled data, warm-start, solve.

        Returns:
            (status value, iterations, primal z~, dual y~), fresh arrays (or None).

        Raises:
            osqp.OSQPException: OSQP refused the warm start.
        """
        self._solver.update(q=q, l=lo, u=hi, Ax=a_data)
        flag = self._solver.warm_start(x=x_ws, y=y_ws)
        if flag:
            raise osqp.OSQPException(flag)
        # In chunks (`MpcTuning.settle_chunk_iter`): stop at the tolerances, at max_iter,
        # or once the first command has settled; each chunk resumes from OSQP's iterates.
        total, first_before = 0, None
        while True:
            res = self._solver.solve(raise_error=False)
            status_val, iters = int(res.info.status_val), int(res.info.iter)
            z, y = res.x, res.y
            total += iters
            if status_val == _SOLVED or total >= self.tuning.max_iter or z is None or y is None:
                return status_val, total, z, y
            if status_val not in _USABLE:
                return status_val, total, z, y
            first = z[self._i_first] * self._d_first
            if not np.isfinite(first).all():
                return status_val, total, z, y
            if first_before is not None and (
                abs(first[0] - first_before[0]) < self.tuning.settle_v_tol_mps
                and abs(first[1] - first_before[1]) < self.tuning.settle_omega_tol_radps
            ):
                return status_val, total, z, y
            first_before = first
            # No warm start here: with warm starting on, the next solve goes on from OSQP's
            # own iterates (x, z, y). A warm start would reset z = A x, and restarting
            # from there slows ADMM down or makes it diverge.

    def _set_half_planes(self, xb: np.ndarray, preds: np.ndarray, clear: np.ndarray) -> int:
        """Write the linearised neighbour half-planes; returns how many neighbours are used.

        The M with the smallest predicted gap |pb_k - o_jk| - c_j over the horizon are used
        (stable: ties keep input order), in their input order, so that a neighbour keeps its
        rows (and its warm-start duals) while the selection and the input order hold.
        """
        n_used: int = min(preds.shape[0], self._n_cons)
        a, lo = self._a_data, self._l
        if n_used:
            d = xb[1:, 0:2] - preds[:, 1:, :]  # (K, N, 2) from each predicted centre to pb_k
            dist = np.sqrt(np.einsum("knc,knc->kn", d, d))  # (K, N)
            if preds.shape[0] > n_used:
                gap = (dist - clear[:, None]).min(axis=1)
                sel = np.sort(np.argsort(gap, kind="stable")[:n_used])
                d, dist, clear = d[sel], dist[sel], clear[sel]
            tiny = dist < 1e-9
            if tiny.any():
                # Nominal on the centre: no direction; push straight back along -heading.
                back = -np.stack((np.cos(xb[1:, 2]), np.sin(xb[1:, 2])), axis=-1)
                d = np.where(tiny[..., None], back[None], d)
                dist = np.where(tiny, 1.0, dist)
                lo[self._hp_rows[:n_used]] = clear[:, None] - np.where(tiny, 0.0, dist)
            else:
                # n . (o - pb) + c = c - |pb - o|, with n = (pb - o) / |pb - o|
                lo[self._hp_rows[:n_used]] = clear[:, None] - dist
            a[self._hx[:n_used]] = d[..., 0] / dist
            a[self._hy[:n_used]] = d[..., 1] / dist
        if n_used < self._hp_active:
            # Rows of neighbours gone since last cycle: zero coefficients, no bound.
            a[self._hx[n_used : self._hp_active]] = 0.0
            a[self._hy[n_used : self._hp_active]] = 0.0
            lo[self._hp_rows[n_used : self._hp_active]] = -_INF
        self._hp_active = n_used
        return n_used

    def _fail(self, x0: np.ndarray, last: np.ndarray, iterations: int) -> MpcResult:
        """Safe braking: v falls at the largest deceleration, omega decays to 0 at its rate.

        Both stay within the bounds and rate limits; the warm start is dropped.
        """
        self.failures += 1
        self.reset()
        dt, n_steps = self.config.dt_s, self._n_steps
        k = np.arange(1, n_steps + 1)
        v = np.maximum(last[0] - self.limits.accel_max_mps2 * dt * k, self.limits.v_min_mps)
        v = np.minimum(v, self.limits.v_max_mps)
        w_mag = np.maximum(abs(last[1]) - self.limits.alpha_max_radps2 * dt * k, 0.0)
        w = np.copysign(w_mag, last[1])
        controls = np.column_stack((v, w))
        return MpcResult(
            v_mps=float(v[0]),
            omega_radps=float(w[0]),
            status=PlanStatus.SOLVER_FAILED,
            iterations=iterations,
            planned_inputs=controls,
            initial_state=x0,
            dt_s=dt,
            max_slack_m=0.0,
        )

    def _check(
        self,
        state: np.ndarray,
        last_command: np.ndarray,
        reference: ReferenceLike,
        neighbours_pred_m: np.ndarray | None,
        clearance_m: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Validate shapes and finiteness; returns copies safe to modify."""
        n1 = self._n_steps + 1
        x0 = np.array(state, dtype=float)
        last = np.array(last_command, dtype=float)
        ref = np.array(
            [
                reference.x_m,
                reference.y_m,
                reference.heading_rad,
                reference.v_mps,
                reference.omega_radps,
            ],
            dtype=float,
        )
        if neighbours_pred_m is None:
            preds = np.zeros((0, n1, 2))
            clear = np.zeros(0)
        else:
            preds = np.asarray(neighbours_pred_m, dtype=float)
            clear = np.asarray(clearance_m, dtype=float)
        if x0.shape != (3,) or last.shape != (2,) or ref.shape != (5, n1):
            raise ValueError(
                f"state (3,), last_command (2,), reference 5 x ({n1},): got {x0.shape}, "
                f"{last.shape}, {ref.shape}"
            )
        if preds.ndim != 3 or preds.shape[1:] != (n1, 2) or clear.shape != (preds.shape[0],):
            raise ValueError(
                f"neighbours_pred_m (K, {n1}, 2), clearance_m (K,): got {preds.shape}, "
                f"{clear.shape}"
            )
        # Fast path: a finite sum proves every term finite; else find the culprit exactly.
        total = x0.sum() + last.sum() + ref.sum() + preds.sum() + clear.sum()
        if not math.isfinite(float(total)):
            names = ("state", "last_command", "reference", "neighbours_pred_m", "clearance_m")
            checked = (x0, last, ref, preds, clear)
            for name, arr in zip(names, checked, strict=True):
                if not np.isfinite(arr).all():
                    raise ValueError(f"{name}: non-finite value")
        return x0, last, ref, preds, clear
