"""Write mpc_reference.json: one fixed MPC QP, solved by the tracker and cross-checked.

    .venv/bin/python tests/unit/agent/planning/data/make_mpc_reference.py

The QP is the first (cold) cycle of `MpcTracker` with the default limits, `MpcConfig` and
`DEFAULT_TUNING`: the state (0, 0.3 m, 0.1 rad), the last command (0.6 m/s, 0), a reference
along the x axis at 1 m/s from x = 0, and one neighbour that starts at (2.5, -0.2) and
moves at (-0.5, 0) m/s with a clearance of 0.8 m. Its solution, the planned (v, omega) of
the 20 steps, is written as the tracker gives it with OSQP's tolerances at 1e-9 (no
settling rule).

Cross-check: the same QP built again here, densely and without the tracker's code (no
sparse matrices, no equilibration, no OSQP), from the formulation in the docstring of
`agent.planning.mpc`, and solved by `scipy.optimize.minimize` (trust-constr, exact
gradients and Hessian).
The largest difference between the two is written into the file; the script fails if it
exceeds `CROSS_CHECK_TOL`.

Run again only when the tracker's formulation or tuning changes on purpose; the test
(`tests/unit/agent/planning/test_mpc.py::test_the_tracker_reproduces_the_stored_reference_solution`)
then shows what moved.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import scipy.optimize

from agent.core.config import MpcConfig, RobotLimits
from agent.planning.mpc import MpcTracker
from agent.planning.mpc_qp import DEFAULT_TUNING

OUT = Path(__file__).with_name("mpc_reference.json")
CROSS_CHECK_TOL = 1e-5
"""Largest difference [m/s, rad/s] allowed between the tracker's and scipy's solutions."""

STATE = [0.0, 0.3, 0.1]
LAST_COMMAND = [0.6, 0.0]
NEIGHBOUR_START_M = [2.5, -0.2]
NEIGHBOUR_VELOCITY_MPS = [-0.5, 0.0]
CLEARANCE_M = 0.8
TRUST_WEIGHT = 1.0


class Reference:
    """Along +x at 1 m/s from the origin, sampled at t = k dt, k = 0..N."""

    def __init__(self, n: int, dt: float) -> None:
        t = dt * np.arange(n + 1)
        self.x_m, self.y_m = t.copy(), np.zeros(n + 1)
        self.heading_rad = np.zeros(n + 1)
        self.v_mps, self.omega_radps = np.ones(n + 1), np.zeros(n + 1)


def neighbour_prediction(n: int, dt: float) -> np.ndarray:
    """(1, N + 1, 2) constant-velocity prediction of the neighbour."""
    t = dt * np.arange(n + 1)
    return (np.array(NEIGHBOUR_START_M) + np.outer(t, NEIGHBOUR_VELOCITY_MPS))[None]


def tracker_solution(limits: RobotLimits, config: MpcConfig) -> np.ndarray:
    """(N, 2) planned inputs of the tracker with tight OSQP tolerances."""
    tight = dataclasses.replace(DEFAULT_TUNING, eps_abs=1e-9, eps_rel=1e-9,
                                settle_chunk_iter=0, max_iter=200_000)
    tracker = MpcTracker(limits, config, tight, TRUST_WEIGHT)
    n, dt = config.horizon_steps, config.dt_s
    res = tracker.solve(np.array(STATE), np.array(LAST_COMMAND), Reference(n, dt),
                        neighbour_prediction(n, dt), np.array([CLEARANCE_M]))
    assert res.status.name == "OK", res.status
    return res.planned_inputs


def scipy_solution(limits: RobotLimits, config: MpcConfig) -> np.ndarray:
    """(N, 2) inputs minimising the tracker's QP, built densely here, solved by trust-constr."""
    tu = DEFAULT_TUNING
    n, dt = config.horizon_steps, config.dt_s
    ref = Reference(n, dt)
    u_min = np.array([limits.v_min_mps, -limits.omega_max_radps])
    u_max = np.array([limits.v_max_mps, limits.omega_max_radps])
    du_max = np.array([limits.accel_max_mps2 * dt, limits.alpha_max_radps2 * dt])
    last = np.clip(LAST_COMMAND, u_min, u_max)
    # Nominal: the reference inputs (a cold start), rolled out exactly.
    ub = np.clip(np.column_stack((ref.v_mps[:n], ref.omega_radps[:n])), u_min, u_max)
    xb = np.zeros((n + 1, 3))
    xb[0] = STATE
    for k in range(n):
        x, y, th = xb[k]
        xb[k + 1] = (x + ub[k, 0] * math.cos(th) * dt, y + ub[k, 0] * math.sin(th) * dt,
                     th + ub[k, 1] * dt)
    # dX = G du: dx_{k+1} = A_k dx_k + B_k du_k, dx_0 = 0.
    g = np.zeros((3 * n, 2 * n))
    for k in range(n):
        th, v = xb[k, 2], ub[k, 0]
        a_k = np.array([[1, 0, -v * math.sin(th) * dt], [0, 1, v * math.cos(th) * dt],
                        [0, 0, 1]])
        b_k = np.array([[math.cos(th) * dt, 0], [math.sin(th) * dt, 0], [0, dt]])
        if k:
            g[3 * k:3 * k + 3] = a_k @ g[3 * k - 3:3 * k]
        g[3 * k:3 * k + 3, 2 * k:2 * k + 2] = b_k
    q_w = np.tile([tu.q_position, tu.q_position, tu.q_heading], n)
    q_w[-3:] *= tu.q_terminal
    e0 = np.column_stack((xb[1:, 0] - ref.x_m[1:], xb[1:, 1] - ref.y_m[1:],
                          np.angle(np.exp(1j * (xb[1:, 2] - ref.heading_rad[1:]))))).ravel()
    r_w = np.tile([tu.r_v, tu.r_omega], n)
    rd_w = np.tile([tu.r_dv, tu.r_domega], n)
    d = np.eye(2 * n) - np.eye(2 * n, k=-2)  # (D u)_k = u_k - u_{k-1}, u_{-1} from `first`
    first = np.concatenate((last, np.zeros(2 * n - 2)))
    a_in = (ub - np.column_stack((ref.v_mps[:n], ref.omega_radps[:n]))).ravel()
    rate0 = d @ ub.ravel() - first
    # 0.5 du' H du + f' du: state error, input error, input change, trust region.
    h = 2 * (g.T @ (q_w[:, None] * g) + np.diag(r_w) + d.T @ (rd_w[:, None] * d)
             + TRUST_WEIGHT * np.eye(2 * n))
    f = 2 * (g.T @ (q_w * e0) + r_w * a_in + d.T @ (rd_w * rate0))
    # Half-planes, k = 1..N: n_k . dp_k + s_k >= c - |pb_k - o_k|.
    o = neighbour_prediction(n, dt)[0, 1:]
    diff = xb[1:, :2] - o
    dist = np.hypot(diff[:, 0], diff[:, 1])
    normal = diff / dist[:, None]
    hp = np.zeros((n, 3 * n))
    for k in range(n):
        hp[k, 3 * k:3 * k + 2] = normal[k]
    hp_du = hp @ g
    w_s = tu.slack_weight

    def cost(z: np.ndarray) -> float:
        du, s = z[:2 * n], z[2 * n:]
        return float(0.5 * du @ h @ du + f @ du + w_s * (s.sum() + s @ s))

    def grad(z: np.ndarray) -> np.ndarray:
        du, s = z[:2 * n], z[2 * n:]
        return np.concatenate((h @ du + f, w_s * (1 + 2 * s)))

    ub_flat = ub.ravel()
    # Inequalities as C z - lo >= 0: input rates both ways, half-planes.
    rate_lo = -np.tile(du_max, n) - rate0
    rate_hi = np.tile(du_max, n) - rate0
    c_rate = np.hstack((d, np.zeros((2 * n, n))))
    c_hp = np.hstack((hp_du, np.eye(n)))
    c_all = np.vstack((c_rate, -c_rate, c_hp))
    lo_all = np.concatenate((rate_lo, -rate_hi, CLEARANCE_M - dist))
    bounds = ([(lo - u0, hi - u0) for u0, lo, hi in
               zip(ub_flat, np.tile(u_min, n), np.tile(u_max, n), strict=True)]
              + [(0.0, np.inf)] * n)
    hessian = np.zeros((3 * n, 3 * n))
    hessian[:2 * n, :2 * n] = h
    hessian[2 * n:, 2 * n:] = 2 * w_s * np.eye(n)
    res = scipy.optimize.minimize(
        cost, np.zeros(3 * n), jac=grad, hess=lambda z: hessian, method="trust-constr",
        bounds=scipy.optimize.Bounds(*np.array(bounds, dtype=float).T),
        constraints=[scipy.optimize.LinearConstraint(c_all, lo_all, np.inf)],
        options={"gtol": 1e-12, "xtol": 1e-14, "maxiter": 20_000})
    assert res.status in (1, 2), res.message
    return ub + res.x[:2 * n].reshape(n, 2)


def main() -> None:
    limits, config = RobotLimits(), MpcConfig()
    ours = tracker_solution(limits, config)
    theirs = scipy_solution(limits, config)
    gap = float(np.abs(ours - theirs).max())
    if gap > CROSS_CHECK_TOL:
        raise SystemExit(f"tracker and scipy differ by {gap:.3g} > {CROSS_CHECK_TOL}")
    text = json.dumps({
        "comment": "One fixed QP of agent.planning.mpc.MpcTracker (its first, cold cycle) and "
                   "its solution; written by make_mpc_reference.py beside this file, which "
                   "says how it was produced and cross-checked.",
        "state": STATE,
        "last_command": LAST_COMMAND,
        "reference": "x = t, y = 0, heading 0, v 1 m/s, omega 0, at t = k dt, k = 0..N",
        "neighbour_start_m": NEIGHBOUR_START_M,
        "neighbour_velocity_mps": NEIGHBOUR_VELOCITY_MPS,
        "clearance_m": CLEARANCE_M,
        "trust_weight": TRUST_WEIGHT,
        "limits": "RobotLimits() defaults",
        "config": "MpcConfig() defaults",
        "tuning": "DEFAULT_TUNING",
        "planned_inputs": [[round(v, 9), round(w, 9)] for v, w in ours.tolist()],
        "cross_check": {"solver": "scipy.optimize.minimize trust-constr on the dense QP",
                        "max_abs_difference": gap},
        "tolerance": {
            "tight": {"what": "the tracker at eps_abs = eps_rel = 1e-9, no settling rule",
                      "atol": 1e-6},
            "default": {"what": "the tracker as it runs (DEFAULT_TUNING: eps 1e-3, settled "
                                "after chunks of 100 iterations); about four times its "
                                "distance from the tight solution when this was written",
                        "atol_first_command": 0.005, "atol": 0.01},
        },
    }, indent=1)
    # Short lists on one line each: [0.75, -0.234493076].
    text = re.sub(r"\[\s+([^\[\]{}]*?)\s+\]",
                  lambda m: "[" + re.sub(r",\s+", ", ", m.group(1)) + "]", text)
    OUT.write_text(text + "\n")
    print(f"wrote {OUT}; tracker vs scipy: max difference {gap:.2e}")


if __name__ == "__main__":
    main()
