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

The weights and solver settings are an `MpcTuning`, the tracker's input (`DEFAULT_TUNING`;
the paper profile's `PAPER_TUNING`), the horizon and the half-planes' margin `MpcConfig` settings.
`agent.planning.mpc_qp` holds them and assembles the QP (`build_qp`: P, A, the constant
parts of q, l and u, the indices of the changing entries, the shifts and the scaling);
this module runs it each cycle.

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
from agent.planning.mpc_qp import DEFAULT_TUNING, OSQP_INF, MpcTuning, build_qp
from agent.planning.unicycle import clamp_command, rollout, rollout_with_trig

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

        qp = build_qp(limits, config, tuning, trust_weight)
        self._qp = qp
        nx, nu = qp.n_x, qp.n_u
        # Written in place each cycle: A's data, q, l, u, and views of their blocks.
        self._a_data = qp.A.data.copy()
        self._q, self._l, self._u = qp.q.copy(), qp.l.copy(), qp.u.copy()
        self._q_x = self._q[:nx].reshape(n_steps, 3)
        self._q_u = self._q[nx : nx + nu].reshape(n_steps, 2)
        self._l_box = self._l[qp.box_rows].reshape(n_steps, 2)
        self._u_box = self._u[qp.box_rows].reshape(n_steps, 2)
        self._l_rate = self._l[qp.rate_rows].reshape(n_steps, 2)
        self._u_rate = self._u[qp.rate_rows].reshape(n_steps, 2)
        self._hp_active = n_cons  # slots whose rows may hold a constraint (all, at setup)
        self._x_zero = np.zeros(self._q.shape[0])
        self._y_zero = np.zeros(self._l.shape[0])

        # Chunks are whole multiples of the rho adaptation interval, so that a chunked
        # solve is the same ADMM run as one call (the adaptation counts from each call).
        chunk = -(-tuning.settle_chunk_iter // _RHO_INTERVAL) * _RHO_INTERVAL
        self._chunk_iter = min(chunk, tuning.max_iter) if chunk > 0 else tuning.max_iter
        self._solver = solver_factory()
        self._solver.setup(
            qp.p_scaled,
            self._q * qp.q_scale,
            sp.csc_matrix((qp.A.data * qp.a_scale, qp.A.indices, qp.A.indptr), shape=qp.A.shape),
            self._l * qp.e_row,
            self._u * qp.e_row,
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
        ub = self._nominal_inputs(ref)
        xb, cos_b, sin_b = rollout_with_trig(x0, ub, dt)
        self._linearise(ub, xb, cos_b, sin_b, last, ref)
        n_used = self._set_half_planes(xb, preds, clear)

        # Inputs are finite, so only an overflow can make q or l non-finite (a is bounded).
        q, lo, hi = self._q, self._l, self._u
        if not math.isfinite(float(q.sum()) + float(lo.sum())):
            return self._fail(x0, last, 0)
        qp = self._qp
        e_row, n_xu = qp.e_row, qp.n_x + qp.n_u
        x_ws, y_ws = self._warm_start()
        try:
            status_val, iterations, z_scaled, y_scaled = self._osqp(
                q * qp.q_scale, lo * e_row, hi * e_row, self._a_data * qp.a_scale, x_ws, y_ws
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
        z = z_scaled * qp.d_var

        u_opt = ub + z[qp.n_x : n_xu].reshape(n_steps, 2)
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

    def _nominal_inputs(self, ref: np.ndarray) -> np.ndarray:
        """(N, 2) the nominal inputs ub_k, within the bounds: the previous solution shifted by
        one step (the last repeated), else the reference's (`ref`: (5, N + 1) from `_check`)."""
        n_steps = self._n_steps
        ub = np.empty((n_steps, 2))
        if self._u_prev is None:
            ub[:, 0] = ref[3, :n_steps]
            ub[:, 1] = ref[4, :n_steps]
        else:
            ub[:-1] = self._u_prev[1:]
            ub[-1] = self._u_prev[-1]
        np.minimum(np.maximum(ub, self._u_min, out=ub), self._u_max, out=ub)
        return ub

    def _linearise(self, ub: np.ndarray, xb: np.ndarray, cos_b: np.ndarray, sin_b: np.ndarray,
                   last: np.ndarray, ref: np.ndarray) -> None:
        """Write this cycle's A_k, B_k entries, q and the input rows of l and u, in place.

        Args:
            ub: (N, 2) nominal inputs; xb: (N + 1, 3) their rollout from x_0.
            cos_b, sin_b: (N,) cosine and sine of the nominal headings 0..N-1.
            last: (2,) u_{-1}, the last applied command.
            ref: (5, N + 1) x, y, heading, v, omega of the reference (`_check`).
        """
        n_steps, dt, qp = self._n_steps, self.config.dt_s, self._qp
        # A: B_k and the v-dependent column of A_k (unicycle.jacobians, entry by entry).
        a, at = self._a_data, qp.entries
        cos_dt = cos_b * dt
        sin_dt = sin_b * dt
        a[at.b00] = cos_dt
        a[at.b10] = sin_dt
        a[at.a02] = -ub[1:, 0] * sin_dt[1:]
        a[at.a12] = ub[1:, 0] * cos_dt[1:]

        # q: state error (heading wrapped), input error and input change against u_{-1}.
        err = xb[1:] - ref[0:3, 1:].T
        err[:, 2] = np.mod(err[:, 2] + np.pi, 2.0 * np.pi) - np.pi
        np.multiply(qp.q_state, err, out=self._q_x)
        g = np.empty((n_steps, 2))  # D ub - e_0 u_{-1}
        np.subtract(ub[0], last, out=g[0])
        np.subtract(ub[1:], ub[:-1], out=g[1:])
        dtg = g.copy()  # D' g
        dtg[:-1] -= g[1:]
        dtg *= qp.rd_w
        np.multiply(qp.r_w, ub - ref[3:5, :n_steps].T, out=self._q_u)
        self._q_u += dtg
        # l, u: input bounds and rates, relative to the nominal.
        np.subtract(self._u_min, ub, out=self._l_box)
        np.subtract(self._u_max, ub, out=self._u_box)
        np.subtract(-self._du_max, g, out=self._l_rate)
        np.subtract(self._du_max, g, out=self._u_rate)

    def _warm_start(self) -> tuple[np.ndarray, np.ndarray]:
        """Scaled primal and dual warm start: zero when cold, else the shifted solution."""
        if self._y_prev is None or self._s_prev is None:  # both or neither
            return self._x_zero, self._y_zero
        # Shifted solution: z = 0 is the nominal; slacks and duals move one step.
        qp = self._qp
        x_ws = self._x_zero.copy()
        x_ws[qp.n_x + qp.n_u :] = self._s_prev[qp.slack_shift] * qp.slack_ws_scale
        return x_ws, self._y_prev[qp.row_shift] * qp.y_ws_scale

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
            first = z[self._qp.i_first] * self._qp.d_first
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
        a, lo, qp = self._a_data, self._l, self._qp
        if n_used:
            d = xb[1:, 0:2] - preds[:, 1:, :]  # (K, N, 2) from each predicted centre to pb_k
            dist = np.sqrt(np.einsum("knc,knc->kn", d, d))  # (K, N)
            if preds.shape[0] > n_used:
                gap = (dist - clear[:, None]).min(axis=1).tolist()
                # A stable sort (ties keep input order), in plain Python: K is at most the
                # neighbour cap, where numpy's argsort and sort cost more than they save.
                sel = sorted(sorted(range(len(gap)), key=gap.__getitem__)[:n_used])
                d, dist, clear = d[sel], dist[sel], clear[sel]
            tiny = dist < 1e-9
            if tiny.any():
                # Nominal on the centre: no direction; push straight back along -heading.
                back = -np.stack((np.cos(xb[1:, 2]), np.sin(xb[1:, 2])), axis=-1)
                d = np.where(tiny[..., None], back[None], d)
                dist = np.where(tiny, 1.0, dist)
                lo[qp.hp_rows[:n_used]] = clear[:, None] - np.where(tiny, 0.0, dist)
            else:
                # n . (o - pb) + c = c - |pb - o|, with n = (pb - o) / |pb - o|
                lo[qp.hp_rows[:n_used]] = clear[:, None] - dist
            a[qp.entries.hx[:n_used]] = d[..., 0] / dist
            a[qp.entries.hy[:n_used]] = d[..., 1] / dist
        if n_used < self._hp_active:
            # Rows of neighbours gone since last cycle: zero coefficients, no bound.
            a[qp.entries.hx[n_used : self._hp_active]] = 0.0
            a[qp.entries.hy[n_used : self._hp_active]] = 0.0
            lo[qp.hp_rows[n_used : self._hp_active]] = -OSQP_INF
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
