"""Frozen configuration of a robot and its planner.

Scenario files name these fields without the unit suffix (`d_safety` -> `d_safety_m`,
`t_max` -> `t_max_s`, `v_max` -> `v_max_mps`); see `world.scenario_file`. SI units throughout.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

PLANNER_NAMES: tuple[str, ...] = ("eifp-mpc", "eifp", "ifp", "orca")

POSITIVE_FIELDS = frozenset({
    "v_max_mps", "omega_max_radps", "accel_max_mps2", "alpha_max_radps2",
    "d_thresh_m", "t_max_s", "sensing_radius_m", "max_neighbors", "max_depth",
    "estimation_window_s", "command_hold_periods", "lookahead_s", "heading_gain",
    "orca_time_horizon_s", "horizon_steps", "dt_s", "max_iter", "spline_first_leg_segments",
    "via_time_max_s",
})
"""Numeric config fields that must be > 0 (by field name, over the three classes)."""
SIGNED_FIELDS = frozenset({"v_min_mps"})
"""Numeric config fields of any sign (`v_min_mps < 0`: the robot may reverse). Every other
numeric field must be >= 0 (weights, margins, caps); None stays allowed where typed."""


def field_range_error(name: str, value: object) -> str | None:
    """What is wrong with `value` for the numeric config field `name`, or None.

    The one set of range rules for configurations: the scenario loader reports it with the
    file and key (`world.scenario_file`), the wire loader as a `ProtocolError` (`protocol`), and
    the dataclasses below refuse to be built with a value it rejects.
    """
    if value is None or isinstance(value, bool) or not isinstance(value, int | float):
        return None  # not numeric: the loaders check types
    if not math.isfinite(value):
        return f"expected a finite number, got {value!r}"
    if name in POSITIVE_FIELDS and value <= 0:
        return f"must be > 0, got {value!r}"
    if name not in POSITIVE_FIELDS and name not in SIGNED_FIELDS and value < 0:
        return f"must be >= 0, got {value!r}"
    return None


def _check_ranges(config: object) -> None:
    """Raise `ValueError` naming the first numeric field of `config` out of its range."""
    for f in dataclasses.fields(config):  # type: ignore[arg-type]
        problem = field_range_error(f.name, getattr(config, f.name))
        if problem is not None:
            raise ValueError(f"{f.name}: {problem}")


@dataclass(frozen=True)
class RobotLimits:
    """Actuation limits of a unicycle robot.

    Args:
        v_max_mps: largest forward speed.
        v_min_mps: smallest forward speed (0: the robot never reverses).
        omega_max_radps: largest |turn rate|.
        accel_max_mps2: largest |dv/dt| a planner may command.
        alpha_max_radps2: largest |d omega/dt| a planner may command.

    Raises:
        ValueError: a field out of range (`field_range_error`), or v_min_mps > v_max_mps.
    """

    v_max_mps: float = 1.1
    v_min_mps: float = 0.0
    omega_max_radps: float = 1.5
    accel_max_mps2: float = 1.5
    alpha_max_radps2: float = 6.0

    def __post_init__(self) -> None:
        _check_ranges(self)
        if self.v_min_mps > self.v_max_mps:
            raise ValueError(
                f"v_min_mps: must be <= v_max_mps ({self.v_max_mps!r}), got {self.v_min_mps!r}")


@dataclass(frozen=True)
class MpcConfig:
    """LTV-MPC tracker solved with OSQP (eIFP-MPC).

    Args:
        horizon_steps: N, number of control steps.
        dt_s: step length of the prediction model (Eq. 1).
        q_position: weight on squared position error per step [1/m^2].
        q_heading: weight on squared heading error per step [1/rad^2].
        q_terminal: multiplier on the last step's state weight.
        r_v: weight on (v - v_ref)^2.
        r_omega: weight on (omega - omega_ref)^2.
        r_dv: weight on squared change of v between steps.
        r_domega: weight on squared change of omega between steps.
        max_constraints: neighbours turned into half-plane constraints (nearest first).
        clearance_margin_m: gap the half-planes keep between discs (the via-point planner
            keeps the larger d_safety; the MPC constraint is the last line of defence).
        slack_weight: linear and quadratic weight on half-plane slack (soft constraints).
            The linear part makes the penalty exact (no slack while it can be avoided) as
            long as a step's half-plane multipliers (one slack per step, shared by its
            half-planes: `agent.planning.mpc`) sum to less than it: in the 16-robot bench crowd
            the largest multiplier of a feasible QP was below 1e3 in 99.86 % of cycles
            (p99 306; measured with a slack per half-plane). 1e3, not the earlier 1e4:
            the larger weight dominated the residual norms OSQP's rho adaptation balances
            and made the iteration tail (bench p99 685-1000 iterations, 1e3: 330-430;
            `orchestrator bench` prints them); the
            braking guard, not the slack, is what keeps the gap (`agent.planning.safety`).
        max_iter: OSQP iteration cap per solve. 1000, not OSQP's usual few hundred: in the
            crowded centre of setups F and G (more so with the wider half-planes of a
            delayed link) 200 iterations often stopped short (`SOLVER_INACCURATE`, the
            iterate used), and such iterates drove robots into each other at 100 ms
            latency (F, link seeds 4, 7, 8: contacts at 200, none at 1000; measured
            before the braking guard and with a slack weight of 1e4). With 1e3 about
            0.2 % of the bench crowd's solves reached it; with the settle rule below, none
            (`orchestrator bench`, N = 8-64). Counted in whole chunks: a cap that is not
            a multiple of the chunk is overshot by less than one chunk.
        settle_chunk_iter: OSQP runs in chunks of this many iterations (rounded up to a
            multiple of 25, OSQP's rho adaptation interval here; 0: one run to
            `max_iter`). The chunks are one uninterrupted ADMM run; after a chunk that
            has not met the tolerances, the solve stops if the first command (the only
            one applied) moved by less than `settle_v_tol_mps` and
            `settle_omega_tol_radps` over the chunk, else it goes on, up to `max_iter` in
            all. Such a stop is `SOLVER_INACCURATE`. Why: the slow QPs of a crowd (many
            active bounds and half-planes) spend their last hundreds of iterations on the
            far end of the horizon. Measured offline on the 262 QPs of a 16-robot bench
            crowd that needed more than 150 iterations: the first command's error against
            a 1e-5 solution, p90 / max, 0.0016 / 0.016 m/s and 0.0024 / 0.043 rad/s with
            chunks of 100 (one run to the tolerances: 0.0007 / 0.016 m/s and 0.0015 /
            0.043 rad/s), their iterations p90 300 instead of 500.
        settle_v_tol_mps: see `settle_chunk_iter` [m/s].
        settle_omega_tol_radps: see `settle_chunk_iter` [rad/s].
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
        braking_guard: the command's speed is capped so the robot can still stop its own
            approach to every disc it faces before the gap falls below `braking_margin_m`,
            given the pose age and one control period of reaction (`agent.planning.safety`; not in
            the paper: the soft half-planes can trade a stopped neighbour's gap away).
        braking_margin_m: gap the braking guard keeps.

    Raises:
        ValueError: a field out of range (`field_range_error`).
    """

    horizon_steps: int = 20
    dt_s: float = 0.1
    q_position: float = 10.0
    q_heading: float = 0.5
    q_terminal: float = 2.0
    r_v: float = 1.0
    r_omega: float = 0.2
    r_dv: float = 2.0
    r_domega: float = 0.5
    max_constraints: int = 4
    clearance_margin_m: float = 0.1
    slack_weight: float = 1.0e3
    max_iter: int = 1000
    settle_chunk_iter: int = 100
    settle_v_tol_mps: float = 0.01
    settle_omega_tol_radps: float = 0.01
    eps_abs: float = 1.0e-3
    eps_rel: float = 1.0e-3
    braking_guard: bool = True
    braking_margin_m: float = 0.05

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class PlannerConfig:
    """Parameters shared by the four planners; each file key maps onto one field.

    Args:
        d_safety_m: safety margin added to the inflated radius L (Eq. 7).
        d_thresh_m: DCPA threshold of Eq. (5); None means 5 * r_robot + d_safety_m.
        t_max_s: TCPA horizon T_max of Eq. (5).
        sensing_radius_m: others farther than this (centre to centre) are not seen.
        max_neighbors: at most this many nearest others enter planning (bounds the work).
        max_depth: IFP/eIFP iteration depth (via-points per plan).
        w_length: w_g of Eq. (14), weight on the normalised length.
        w_distance: w_d of Eq. (14), weight on the inverse distance to predicted paths [m].
        w_angle: w_a of Eq. (14), weight on the angular misalignment.
        ghost_horizon_s: how far ahead a neighbour's ghost goal is projected.
        ghost_clearance_m: candidates closer than this to a ghost path are discarded;
            None means the pair's inflated radius L.
        side_hysteresis: a via-point on the other side than last time for the same threat
            must beat the kept side's cost by this fraction.
        right_hand_margin: on a first choice against another robot, LEFT must beat RIGHT by
            this fraction of the cost (a right-hand traffic convention that every robot
            shares, so mirrored encounters resolve consistently without communication).
        threat_commitment: eIFP keeps resolving a threat it chose a side for until it has
            passed it (TCPA <= 0), instead of dropping it when its own swerve makes the
            threat's DCPA exceed D_thresh (which makes the robot weave).
        encounter_rules: eIFP follows the shared give-way/stand-on convention of
            `agent.planning.encounters` against other robots (not in the paper; False: the paper's
            eIFP, cost-based sides only).
        stand_on_emergency_s: a robot standing on resolves the other after all once TCPA
            is below this with DCPA inside the inflated radius (`agent.planning.encounters`).
        spline_clamp_heading: the reference spline leaves the robot along its heading
            (clamped start) when the first via-point is within 30 degrees of it, instead of
            the paper's natural end conditions (`agent.planning.spline.build_reference`). Spline
            only (`reference_lines_arcs` false); the lines and arcs have their start arc.
        spline_first_leg_segments: the reference spline's first leg (robot to first
            via-point) is cut into this many equal parts by extra knots, so the reference
            runs along the straight leg the via-point was built for
            (`agent.planning.spline.split_first_leg`); 1 is the paper's spline through the
            waypoints alone. Spline only (`reference_lines_arcs` false). Off (1) by
            default: measured on the spline (lockstep, 5 cm jitter, seeds
            0-9, oscillations per robot F / G): 1: 3.09 / 6.75; 3: 3.54 / 4.62; 4: 3.48 /
            5.02; 6: 3.93 / 9.25; every run arrived with no contact. With 3 it also lowers
            A and D and raises B, C and E, and the effect is not monotonic in the count,
            so it is an option until that is understood (README, "Results"; at 100 ms
            latency with 10 % loss, 3 parts: F and G 0/20 runs touch).
        reference_lines_arcs: eIFP-MPC's reference follows the waypoint legs with arcs at the
            corners and a start arc along the heading (`agent.planning.spline.LineArcPath`), with
            no turn-rate feed-forward, instead of the paper's cubic spline through the
            waypoints (False: the spline, with `spline_clamp_heading` and
            `spline_first_leg_segments`). On by default (not in the paper): measured
            (lockstep, 5 cm jitter, seeds 0-9, oscillations per robot, spline -> lines and
            arcs; README, "Results", stop 22): A 0.50 -> 0, C 0.30 -> 0, D 2.12 -> 0.10,
            F 3.09 -> 2.73, G 6.75 -> 3.94, but B 0.37 -> 1.47 and E 1.28 -> 2.12; every
            run arrived with no contact.
        path_corner_radius_m: radius of the arcs at the via-points (lines and arcs).
        path_start_radius_m: radius of the start arc along the heading (lines and arcs;
            0: none, the path starts along the first leg).
        primary_hysteresis: eIFP resolves the threat it resolved first last cycle first
            again while its TCPA is within `primary_margin_s` of the most imminent one's,
            instead of re-ranking from scratch. Off by default: in lockstep trials on the
            spline it lowered setup D's oscillations (2 -> 0.25-1) but raised setup G's
            (6.8 -> 8.1 per robot, mean over 6 seeds). On the lines and arcs (stop 22,
            README) it is the lead for the dense crossings, not yet measured enough to be a
            default: lockstep, seeds 0-3, F / G per robot: off 2.48 / 3.91; margin 1 s
            2.06 / 4.59 (10 seeds); 2 s 2.00 / 3.66; 2.5 s and 3 s 4.15 and 3.96 / 1.98.
            Stop 23, seeds 0-9: off 2.73 / 3.94, 3 s 3.72 / 1.99 (F's centre jams); no
            variant tried brought both under 2 (README, "Stop 23").
        primary_margin_s: see `primary_hysteresis` [s].
        threats_within_inflated: eIFP-MPC counts an other as a threat (Eq. 5) only when its
            DCPA falls inside the pair's inflated radius L (Eq. 7), a predicted incursion,
            instead of within the paper's D_thresh = 5 r + d_safety (2.8 m against L = 1.3 m
            for two 0.5 m robots); the legs are checked against L either way, and a set
            `d_thresh_m` still wins. eIFP-MPC only (`agent.planning.ifp.CycleRules`; ifp and eifp
            keep the paper's). On by default with the three fields below (not in the
            paper): D_thresh alone was non-monotonic in the dense crossings (lockstep, 5 cm
            jitter, seeds 0-9, F / G per robot: 1.3 m 2.69 / 3.28 with one G run stuck,
            1.6 m 3.01 / 2.76, 2.0 m 4.67 / 2.45, 2.8 m 2.73 / 3.94); with the rules
            below 1.81 / 1.72 (README, "Stop 24").
        threat_release_margin_m: with `threats_within_inflated`, an other that eIFP-MPC's
            plan resolved last cycle stays a threat while its DCPA is within L + this, so a
            threat that the robot's own swerve pushes just past L is not dropped and picked
            up again next cycle (lockstep, seeds 0-9, with the other rules, F / G per
            robot: 0 1.84 / 1.90; 0.5 m 1.81 / 1.72; 1.5 m, out at D_thresh, 1.94 / 1.72).
        via_margin_m: how far outside its inflated disc eIFP-MPC places a via-point (ifp and
            eifp: `agent.planning.ifp.VIA_MARGIN_M`, 0.05 m). The reference's arc at a via-point
            cuts the corner towards the disc it turns round, so a via-point on the disc
            put the robot inside it, and into an escape, at about every corner (with the
            other three: 0.05 m F 2.38 / G 1.91; 0.2 m 1.94 / 2.26; 0.3 m 1.84 / 1.90).
        escape_hysteresis_m: an eIFP-MPC escape goes on from the same disc until the robot
            is this far outside it, towards a point that far out (0: only while inside).
            Two robots standing on each other's disc boundary otherwise switched between
            escaping and planning round each other every cycle and turned on the spot
            until the time limit (G, seed 8, with `threats_within_inflated`).
        head_on_hold_s: eIFP-MPC resolves a head-on threat (course within
            `agent.planning.ifp.HEAD_ON_MAX_DEG` of reciprocal) that it resolved first last cycle
            first again while its TCPA is within this of the most imminent one's
            (`primary_hysteresis` for head-on threats only; 0: off). Stop 23 measured it
            alone: F 2.73 -> 2.22, G 3.94 -> 4.03.
        via_time_max_s: eIFP-MPC drops a via-point candidate that the robot would reach
            only after this long at top speed (the velocity cone's lambda*, Eq. 13); None:
            no cap (ifp and eifp keep none). 8 s is the threat horizon `t_max_s`. With the
            others as fast as the robot, a tangent point that recedes nearly as fast as
            the robot closes on it is met after tens to thousands of seconds: the
            via-point lay far down the other's track (measured: 2.2 km away), and the
            robot turned along that track. Stop 25 (README): with `primary_fallback`,
            F / G per robot, lockstep with the distributed runs' staggered planning
            slots, seeds 0-9: 2.09 / 1.94 -> 1.45 / 1.14.
        primary_fallback: when eIFP-MPC's first-ranked threat has no feasible via-point
            (both candidates past `via_time_max_s`, say), the next threat in rank order
            that has one is resolved first; without it the cycle gives up (NO_FEASIBLE,
            straight to the goal) and the next cycle swerves again. The cap alone: F / G
            1.45 / 2.44 (G's robots flipped between the goal and a via-point).
        direct_leg_check: when Eq. (5) finds no threat, the direct leg robot -> goal still
            goes through IFP's leg check (`agent.ifp`, step 4: closest approach on the leg
            at top speed against the inflated radius L, within T_max), so a robot standing
            still (v_r = 0) sees a static obstacle on its way. Not in the paper, where a
            threat is declared by Eq. (5) alone: the leg check flags others whose TCPA is
            past T_max (it measures the gap at the horizon's end), and then drops them again
            as the two swerve, which made the paper profile weave (`paper_config`). The
            legs after a via-point are checked either way (the IFP iteration).
        goal_tcpa_filter: threats of Eq. (5) whose TCPA is more than
            `agent.ifp.GOAL_TCPA_MARGIN_S` past the robot's time to its goal at top speed are
            not resolved (an overshoot near the goal would otherwise send the robot round it).
            Not in the paper.
        estimation_window_s: history length used to estimate others' velocity and linearity.
            0.75 s (was 0.5): measured, it cut the reversals in the dense crossings
            (lockstep, 5 cm jitter, seeds 0-9: F 4.28 -> 3.09, G 8.30 -> 6.75 per robot;
            README, "Results"); 1.25 s and longer made them worse again. With poses 0.1 s
            apart (lockstep, and a distributed robot reading its pose slot) the 8-sample
            history (`NeighborTracker`) spans 0.7 s: 0.75 s fits every sample it holds,
            1.0 s the same ones, and from 1.25 s on (spacing window / 6 > 0.2 s) it keeps
            every other pose. The braking guard's allowance for an estimate's lag
            (window / 2) grows with it (`agent.planning.safety`).
        command_hold_periods: each command tells the world to apply it for at most this
            many control periods (`protocol.CommandMsg.hold_s`); a command that is not
            followed in time (lost or late on the link) then gives way to braking instead
            of acting until the world's time-out. 1.5: one period plus half a period of
            jitter between two commands before the world brakes (not in the paper).
        lookahead_s: how far ahead on the reference the tracking law aims.
        heading_gain: proportional gain of the tracking law on heading error [1/s].
        orca_time_horizon_s: ORCA's time horizon for other agents.
        mpc: the MPC tracker's parameters (eIFP-MPC only).

    Raises:
        ValueError: a field out of range (`field_range_error`).
    """

    d_safety_m: float = 0.3
    d_thresh_m: float | None = None
    t_max_s: float = 8.0
    sensing_radius_m: float = 10.0
    max_neighbors: int = 10
    max_depth: int = 3
    w_length: float = 1.0
    w_distance: float = 1.0
    w_angle: float = 0.3
    ghost_horizon_s: float = 4.0
    ghost_clearance_m: float | None = None
    side_hysteresis: float = 0.15
    right_hand_margin: float = 0.05
    threat_commitment: bool = False
    encounter_rules: bool = True
    spline_clamp_heading: bool = True
    spline_first_leg_segments: int = 1
    reference_lines_arcs: bool = True
    path_corner_radius_m: float = 1.0
    path_start_radius_m: float = 5.0
    primary_hysteresis: bool = False
    primary_margin_s: float = 1.0
    threats_within_inflated: bool = True
    threat_release_margin_m: float = 0.5
    via_margin_m: float = 0.3
    escape_hysteresis_m: float = 0.1
    head_on_hold_s: float = 3.0
    via_time_max_s: float | None = 8.0
    primary_fallback: bool = True
    stand_on_emergency_s: float = 2.0
    direct_leg_check: bool = True
    goal_tcpa_filter: bool = True
    estimation_window_s: float = 0.75
    command_hold_periods: float = 1.5
    lookahead_s: float = 0.6
    heading_gain: float = 2.5
    orca_time_horizon_s: float = 4.0
    mpc: MpcConfig = field(default_factory=MpcConfig)

    def __post_init__(self) -> None:
        _check_ranges(self)

    def dcpa_threshold_m(self, robot_radius_m: float) -> float:
        """D_thresh of Eq. (5): configured, or 5 * r_robot + d_safety."""
        if self.d_thresh_m is not None:
            return self.d_thresh_m
        return 5.0 * robot_radius_m + self.d_safety_m


PAPER_MPC_OVERRIDES: dict[str, object] = {
    "q_terminal": 1.0,
    "r_dv": 0.0,
    "r_domega": 0.0,
    "braking_guard": False,
}
"""`MpcConfig` fields that `paper_config` changes: the paper's J (Eq. 21) has one state
weight Q for every step (no terminal multiplier) and an input weight R, no input-rate
terms; there is no braking guard. The inputs' rate bounds stay: they are the robot's
actuation limits (`RobotLimits`), which the world enforces too."""

PAPER_OVERRIDES: dict[str, object] = {
    # eIFP's additions (not in the paper): encounter rules, side memory, right-hand rule.
    "encounter_rules": False,
    "side_hysteresis": 0.0,
    "right_hand_margin": 0.0,
    "threat_commitment": False,
    "primary_hysteresis": False,
    # IFP cycle: threats by Eq. (5) alone, with D_thresh = 5 r + d_safety.
    "direct_leg_check": False,
    "goal_tcpa_filter": False,
    "d_thresh_m": None,
    # eIFP-MPC's cycle rules (agent.ifp.CycleRules): all off, the paper's cycle.
    "threats_within_inflated": False,
    "threat_release_margin_m": 0.0,
    "via_margin_m": 0.05,  # agent.ifp.VIA_MARGIN_M, as ifp and eifp (an open choice)
    "escape_hysteresis_m": 0.0,
    "head_on_hold_s": 0.0,
    "via_time_max_s": None,
    "primary_fallback": False,
    # The paper's cubic spline through the waypoints, natural ends (Eq. 19).
    "reference_lines_arcs": False,
    "spline_clamp_heading": False,
    "spline_first_leg_segments": 1,
    # The paper limits neither the sensing range nor the neighbour count.
    "sensing_radius_m": 1.0e3,
    "max_neighbors": 1000,
}
"""`PlannerConfig` fields that `paper_config` sets (every addition of ours off)."""


def paper_config(base: PlannerConfig | None = None, **overrides: object) -> PlannerConfig:
    """The paper's method as written (Eqs. 6-22): every addition of this project off.

    IFP, eIFP and eIFP-MPC then run the threat test of Eq. (6) with D_thresh, the TCPA
    ranking (7), the inflated radius (8), the tangents (9)-(11), the velocity cone
    (12)-(14), the cost (15)-(17) with plain argmin (18) (exact ties to S1, RIGHT), the
    natural cubic spline (19) and the MPC (20)-(22) with the neighbours' predictions as
    soft constraints. What the paper leaves open keeps the readings documented in the
    modules and in docs/method.md.

    Args:
        base: the configuration to start from (weights, d_safety, T_max, ...); None: the
            defaults.
        overrides: further fields, applied last (``mpc`` replaces the paper's MpcConfig).

    Returns:
        A frozen `PlannerConfig`.
    """
    base = base if base is not None else PlannerConfig()
    fields_ = dict(PAPER_OVERRIDES)
    fields_["mpc"] = dataclasses.replace(base.mpc, **PAPER_MPC_OVERRIDES)
    fields_.update(overrides)
    return dataclasses.replace(base, **fields_)


PROFILES: tuple[str, ...] = ("default", "paper")
"""Named planner configurations: ``default`` (this project's eIFP-MPC) and ``paper`` (the
paper's method as written, `paper_config`)."""


def profile_config(profile: str, base: PlannerConfig | None = None) -> PlannerConfig:
    """The `PlannerConfig` of a named profile (`PROFILES`), built on `base`.

    Raises:
        ValueError: an unknown profile name.
    """
    if profile == "paper":
        return paper_config(base)
    if profile == "default":
        return base if base is not None else PlannerConfig()
    raise ValueError(f"unknown profile {profile!r}; expected one of {', '.join(PROFILES)}")


def is_paper_config(config: PlannerConfig) -> bool:
    """Whether `config` has every field `paper_config` sets at the paper's value."""
    for name, value in PAPER_OVERRIDES.items():
        if getattr(config, name) != value:
            return False
    return all(getattr(config.mpc, name) == value for name, value in PAPER_MPC_OVERRIDES.items())


def paper_file_defaults() -> dict[str, object]:
    """`PAPER_OVERRIDES` as scenario-file `defaults` keys (unit suffixes stripped, as
    `world.scenario_file` reads them), ``mpc`` nested: paste into a scenario's `defaults`."""
    suffixes = ("_mps2", "_radps2", "_radps", "_mps", "_m", "_s")

    def key(name: str) -> str:
        for suffix in suffixes:
            if name.endswith(suffix):
                return name[: -len(suffix)]
        return name

    out: dict[str, object] = {key(k): v for k, v in PAPER_OVERRIDES.items()}
    out["mpc"] = {key(k): v for k, v in PAPER_MPC_OVERRIDES.items()}
    return out
