"""Frozen configuration of a robot and its planner.

`PlannerConfig` holds the user-facing planner settings, grouped in small frozen
sub-configs (`safety`, `threats`, `cost`, `reference`, `mpc`, `orca`), and the `profile`
that switches this project's additions to the paper's method on (``default``) or off
(``paper``). Every setting is read by a named planner (`SETTINGS` lists which); what is
not a setting is a module constant next to the code that uses it.

Scenario files name the sub-configs as nested mappings and the fields without the unit
suffix (`safety: {d_safety: 0.3}`, `threats: {t_max: 8}`, `mpc: {dt: 0.1}`); see
`world.scenario_file`. SI units throughout.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

PLANNER_NAMES: tuple[str, ...] = ("eifp-mpc", "eifp", "ifp", "orca")

MECHANISM_NAMES: tuple[str, ...] = (
    "direct_leg_check", "goal_tcpa_filter", "encounter_rules", "inflated_threats", "commitment",
    "via_margin_m", "escape_band_m", "escape_all", "horizon_via_points",
    "lines_arcs", "clamp_heading", "braking_guard", "keep_plan", "routing", "liveness",
    "turn_when_stuck", "goal_guard", "passages", "make_way", "lanes")
"""The additions to the paper's cycle that `PlannerConfig.without` can switch off: the fields
of `agent.planning.mechanisms.Mechanisms` (a unit test keeps the two lists equal)."""

PROFILES: tuple[str, ...] = ("default", "paper", "lanes")
"""Planner profiles: ``default`` (this project's additions on), ``paper`` (the paper's
method as written, `paper_config`) and ``lanes`` (the default and, for eIFP-MPC, lanes in
corridors: `agent.planning.mechanisms.Mechanisms.lanes`, an experiment not in the default;
docs/results.md, "Lanes in corridors: an opt-in profile")."""

POSITIVE_FIELDS = frozenset({
    "v_max_mps", "omega_max_radps", "accel_max_mps2", "alpha_max_radps2",
    "t_max_s", "sensing_radius_m", "max_neighbors", "max_depth",
    "horizon_steps", "dt_s", "time_horizon_s",
})
"""Numeric config fields that must be > 0 (by field name, over every config class)."""
SIGNED_FIELDS = frozenset({"v_min_mps"})
"""Numeric config fields of any sign (`v_min_mps < 0`: the robot may reverse). Every other
numeric field must be >= 0 (weights, margins)."""


def field_range_error(name: str, value: object) -> str | None:
    """What is wrong with `value` for the numeric config field `name`, or None.

    The one set of range rules for configurations: the scenario loader reports it with the
    file and key (`world.scenario_file`), the wire loader as a `ProtocolError`
    (`eifp_wire.codec.load_dataclass`), and the dataclasses below refuse to be built with a
    value it rejects.
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


def _check_ranges(config: DataclassInstance) -> None:
    """Raise `ValueError` naming the first numeric field of `config` out of its range."""
    for f in dataclasses.fields(config):
        problem = field_range_error(f.name, getattr(config, f.name))
        if problem is not None:
            raise ValueError(f"{f.name}: {problem}")


@dataclass(frozen=True)
class RobotLimits:
    """Actuation limits (Eq. 2) of a unicycle robot.

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
class SafetyConfig:
    """How much room the robots keep.

    Args:
        d_safety_m: margin added to the pair's radii, L = r_i + r_j + d_safety (Eq. 8);
            read by ifp, eifp and eifp-mpc (tangents, escape) and orca (every disc grows
            by half of it).
        braking_margin_m: gap eIFP-MPC's braking guard keeps (`agent.planning.safety`).
    """

    d_safety_m: float = 0.3
    braking_margin_m: float = 0.05

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class ThreatConfig:
    """Which others a robot plans against.

    Args:
        t_max_s: T_max of Eq. (6), the horizon of the threat test; also the latest a
            via-point may be reached (lambda*, Eq. 14) in the default profile. Read by ifp,
            eifp and eifp-mpc.
        sensing_radius_m: others farther than this (centre to centre) are not seen; read by
            every planner and by the robot's estimator.
        max_neighbors: at most this many nearest others enter planning; read by every
            planner.
    """

    t_max_s: float = 8.0
    sensing_radius_m: float = 10.0
    max_neighbors: int = 10

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class CostConfig:
    """eIFP's via-point cost (Eq. 15) and its side commitment; read by eifp and eifp-mpc.

    Args:
        w_length: w_g, weight on the normalised length (Eq. 16).
        w_distance: w_d, weight on the inverse distance to predicted paths [m].
        w_angle: w_a, weight on the angular misalignment (Eq. 17).
        side_hysteresis: a via-point on the other side of a threat than last cycle's must
            cost less than (1 - this) times the kept side's (0: plain argmin, Eq. 18).
    """

    w_length: float = 1.0
    w_distance: float = 1.0
    w_angle: float = 0.3
    side_hysteresis: float = 0.15

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class ReferenceConfig:
    """The waypoint plan and the path through it.

    Args:
        max_depth: via-points per plan (the IFP iteration); read by ifp, eifp and eifp-mpc.
        corner_radius_m: radius of the arcs that join the legs at the via-points of
            eIFP-MPC's lines-and-arcs reference (`agent.planning.spline.LineArcPath`).
    """

    max_depth: int = 3
    corner_radius_m: float = 1.0

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class MpcConfig:
    """eIFP-MPC's tracker (Eqs. 20-22); read by eifp-mpc only. Its weights and solver
    settings are constants of `agent.planning.mpc_qp`.

    Args:
        horizon_steps: N, the number of control steps.
        dt_s: step of the prediction model (Eq. 20).
        clearance_margin_m: gap the neighbour half-planes keep between discs.
    """

    horizon_steps: int = 20
    dt_s: float = 0.1
    clearance_margin_m: float = 0.1

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class OrcaConfig:
    """The ORCA baseline; read by orca only.

    Args:
        time_horizon_s: ORCA's time horizon for other agents.
    """

    time_horizon_s: float = 4.0

    def __post_init__(self) -> None:
        _check_ranges(self)


@dataclass(frozen=True)
class PlannerConfig:
    """The planner settings of a run, shared by its robots; see `SETTINGS`.

    Args:
        safety, threats, cost, reference, mpc, orca: the sub-configs.
        profile: ``default`` (this project's additions on), ``paper`` (the paper's method
            as written; `paper_config`) or ``lanes`` (the default with lanes in
            corridors). The planners derive their mechanisms from it
            (`agent.planning.mechanisms.mechanisms`).
        without: comma-separated `MECHANISM_NAMES` switched off (set to the paper's value)
            in the default profile: ablations (``"routing,liveness"``); empty: none.

    Raises:
        ValueError: an unknown profile or mechanism name (the sub-configs check their own
            ranges).
    """

    safety: SafetyConfig = field(default_factory=SafetyConfig)
    threats: ThreatConfig = field(default_factory=ThreatConfig)
    cost: CostConfig = field(default_factory=CostConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    orca: OrcaConfig = field(default_factory=OrcaConfig)
    profile: str = "default"
    without: str = ""

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ValueError(
                f"profile: expected one of {', '.join(PROFILES)}, got {self.profile!r}")
        unknown = [n for n in self.without_names if n not in MECHANISM_NAMES]
        if unknown:
            raise ValueError(f"without: unknown mechanism {unknown[0]!r}; expected names "
                             f"from {', '.join(MECHANISM_NAMES)}")

    @property
    def without_names(self) -> tuple[str, ...]:
        """The mechanisms `without` switches off, in the order given."""
        return tuple(n.strip() for n in self.without.split(",") if n.strip())

    @property
    def is_paper(self) -> bool:
        """Whether the paper's method runs as written (every addition off)."""
        return self.profile == "paper"

    def dcpa_threshold_m(self, robot_radius_m: float) -> float:
        """D_thresh of Eq. (6): 5 r_robot + d_safety."""
        return 5.0 * robot_radius_m + self.safety.d_safety_m

    def with_settings(self, **settings: object) -> PlannerConfig:
        """A copy with settings replaced by dotted name: ``with_settings(**{"cost.w_angle":
        0.5})``; a plain name (``profile``) replaces a field of `PlannerConfig` itself.

        Raises:
            ValueError: an unknown name, or a value out of range.
        """
        top: dict[str, Any] = {}  # each value has its field's type: __post_init__ checks
        groups: dict[str, dict[str, object]] = {}
        for name, value in settings.items():
            group, _, key = name.rpartition(".")
            if group:
                groups.setdefault(group, {})[key] = value
            else:
                top[key] = value
        for group, values in groups.items():
            sub = getattr(self, group, None)
            if not dataclasses.is_dataclass(sub) or isinstance(sub, type):
                raise ValueError(f"{group}: not a sub-config of PlannerConfig")
            known = {f.name for f in dataclasses.fields(sub)}
            unknown = sorted(set(values) - known)
            if unknown:
                raise ValueError(f"{group}.{unknown[0]}: not a setting of {group}")
            top[group] = dataclasses.replace(sub, **values)
        known_top = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(top) - known_top)
        if unknown:
            raise ValueError(f"{unknown[0]}: not a field of PlannerConfig")
        return dataclasses.replace(self, **top)


SUB_CONFIGS: tuple[str, ...] = ("safety", "threats", "cost", "reference", "mpc", "orca")
"""The sub-config fields of `PlannerConfig`, in order."""

SETTINGS: dict[str, tuple[str, ...]] = {
    "safety.d_safety_m": ("ifp", "eifp", "eifp-mpc", "orca"),
    "safety.braking_margin_m": ("eifp-mpc",),
    "threats.t_max_s": ("ifp", "eifp", "eifp-mpc"),
    "threats.sensing_radius_m": ("ifp", "eifp", "eifp-mpc", "orca"),
    "threats.max_neighbors": ("ifp", "eifp", "eifp-mpc", "orca"),
    "cost.w_length": ("eifp", "eifp-mpc"),
    "cost.w_distance": ("eifp", "eifp-mpc"),
    "cost.w_angle": ("eifp", "eifp-mpc"),
    "cost.side_hysteresis": ("eifp", "eifp-mpc"),
    "reference.max_depth": ("ifp", "eifp", "eifp-mpc"),
    "reference.corner_radius_m": ("eifp-mpc",),
    "mpc.horizon_steps": ("eifp-mpc",),
    "mpc.dt_s": ("eifp-mpc",),
    "mpc.clearance_margin_m": ("eifp-mpc",),
    "orca.time_horizon_s": ("orca",),
}
"""Every user-facing planner setting (sub-config.field) and the planners that read it."""

PAPER_OVERRIDES: dict[str, object] = {
    "profile": "paper",
    "cost.side_hysteresis": 0.0,
    "threats.sensing_radius_m": 1.0e3,
    "threats.max_neighbors": 1000,
}
"""What `paper_config` sets: the ``paper`` profile (every addition of this project off:
`agent.planning.mechanisms.PAPER_MECHANISMS`, the paper's MPC weights and no braking guard,
`agent.planning.mpc_qp.PAPER_TUNING`), plain argmin (Eq. 18), and neither a sensing range nor
a neighbour cap, which the paper does not have."""


def paper_config(base: PlannerConfig | None = None, **settings: object) -> PlannerConfig:
    """The paper's method as written (Eqs. 1-22): every addition of this project off.

    IFP, eIFP and eIFP-MPC then run the threat test of Eq. (6) with D_thresh, the TCPA
    ranking (7), the inflated radius (8), the tangents (9)-(11), the velocity cone
    (12)-(14), the cost (15)-(17) with plain argmin (18) (exact ties to S1, RIGHT), the
    natural cubic spline (19) and the MPC (20)-(22) with the neighbours' predictions as
    soft constraints. What the paper leaves open keeps the readings documented in the
    modules and in docs/method.md.

    Args:
        base: the configuration to start from (weights, d_safety, T_max, ...); None: the
            defaults.
        settings: further settings by dotted name (`PlannerConfig.with_settings`), applied
            last.

    Returns:
        A frozen `PlannerConfig`.
    """
    base = base if base is not None else PlannerConfig()
    return base.with_settings(**PAPER_OVERRIDES).with_settings(**settings)


def profile_config(profile: str, base: PlannerConfig | None = None) -> PlannerConfig:
    """The `PlannerConfig` of a named profile (`PROFILES`), built on `base`.

    Raises:
        ValueError: an unknown profile name.
    """
    if profile == "paper":
        return paper_config(base)
    if profile == "default":
        return base if base is not None else PlannerConfig()
    if profile == "lanes":
        return dataclasses.replace(base if base is not None else PlannerConfig(),
                                   profile="lanes")
    raise ValueError(f"unknown profile {profile!r}; expected one of {', '.join(PROFILES)}")


def setting(config: PlannerConfig, name: str) -> object:
    """The value of a setting by dotted name (``cost.w_angle``, ``profile``)."""
    value: object = config
    for part in name.split("."):
        value = getattr(value, part)
    return value


def is_paper_config(config: PlannerConfig) -> bool:
    """Whether `config` has every setting `paper_config` sets at the paper's value."""
    return all(setting(config, name) == value for name, value in PAPER_OVERRIDES.items())


def file_key(field_name: str) -> str:
    """The scenario-file key of a config field: its name without the unit suffix."""
    for suffix in ("_radps2", "_radps", "_mps2", "_mps", "_m", "_s"):
        if field_name.endswith(suffix) and len(field_name) > len(suffix):
            return field_name[: -len(suffix)]
    return field_name


def paper_file_defaults() -> dict[str, object]:
    """`PAPER_OVERRIDES` but the profile as scenario-file `defaults` keys (nested by
    sub-config, unit suffixes stripped, as `world.scenario_file` reads them); the profile
    itself is the file's top-level `profile: paper`."""
    out: dict[str, dict[str, object]] = {}
    for name, value in PAPER_OVERRIDES.items():
        group, _, key = name.rpartition(".")
        if group:
            out.setdefault(group, {})[file_key(key)] = value
    return dict(out)
