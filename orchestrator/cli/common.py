"""What the subcommands share: bad-input errors, the progress line, the run summary, the
run and fault flags, output-name helpers."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from agent.core.scenario import Scenario
from agent.flags import add_link_fault_flags

if TYPE_CHECKING:
    from world.sim.faults import FaultPlan

MODES = ("distributed", "lockstep")
DEFAULT_RUNS_DIR = Path("runs")


class BadInput(Exception):
    """A bad option value (exit status 2)."""


SEED_JITTER_M = 0.05
"""Start jitter [m] a nonzero seed gives by default where the scenario does not draw from the
seed (setups A-G, scenario files, the fixed families): without it every seed of such a
scenario would run the same (in lockstep, byte for byte). Seed 0 runs the scenario as
written."""
JITTER_HELP = (f"move each start by up to this much, uniform in a disc, drawn from the seed "
               f"(default: 0 for seed 0; for other seeds {SEED_JITTER_M:g} where the scenario "
               "does not draw from the seed, so that every seed differs; 0 for the seeded "
               "families)")


def start_jitter_m(setup: str, seed: int, requested: float | None, *,
                   agents: int | None = None) -> float:
    """The start jitter of a run: `requested` if given, else `SEED_JITTER_M` for a nonzero
    seed of a scenario that does not draw from the seed, else 0.

    Raises:
        ScenarioError: an unknown setup or a bad size (as `families.resolve`).
    """
    if requested is not None:  # checked where it is used (`families.jitter_starts`)
        return requested
    if seed == 0:
        return 0.0
    from orchestrator.experiments.families import resolve

    seeded = resolve(setup, agents=agents, seed=0) != resolve(setup, agents=agents, seed=1)
    return 0.0 if seeded else SEED_JITTER_M


def planner_label(scenario: Scenario) -> str:
    names = sorted({r.planner for r in scenario.robots})
    return names[0] if len(names) == 1 else "mixed"


def split_list(text: str) -> list[str]:
    """The items of a comma-separated list, stripped, empty ones dropped."""
    return [x.strip() for x in text.split(",") if x.strip()]


def add_link_args(p: argparse.ArgumentParser) -> None:
    """The link faults of every pose and command link, and the latency compensation switch."""
    group = add_link_fault_flags(p, "every pose and command link")
    group.add_argument("--no-latency-compensation", action="store_true",
                       help="robots plan on poses as stamped (no forward prediction by age)")


def add_fault_args(p: argparse.ArgumentParser) -> None:
    add_link_args(p)
    g = p.add_argument_group("robot faults (T, DUR in sim seconds)")
    g.add_argument("--slow-robot", action="append", default=[], metavar="I:MS",
                   help="robot I's commands leave MS ms late (a CPU-starved robot)")
    g.add_argument("--robot-rate", action="append", default=[], metavar="I:HZ[:PHASE_S]",
                   help="robot I plans at HZ, its slots offset by PHASE_S")
    g.add_argument("--kill-robot", action="append", default=[], metavar="I@T",
                   help="SIGKILL robot I at T")
    g.add_argument("--stop-robot", action="append", default=[], metavar="I@T:DUR",
                   help="SIGSTOP robot I at T, SIGCONT at T + DUR")
    g.add_argument("--restart-robot", action="append", default=[], metavar="I@T",
                   help="SIGKILL robot I at T and start it again with the same id")


def fault_plan(args: argparse.Namespace, scenario: Scenario, *, links: bool = True
               ) -> FaultPlan | None:
    """The `FaultPlan` of the fault flags, checked against `scenario` (robot ids, lockstep
    rates), or None when no fault flag is given. `links=False` leaves the link flags and
    the seed out: `stress` sets those per level and run, the robot faults apply to all."""
    from world.sim.faults import FaultSpecError, build_plan

    link_flags = dict(
        latency_ms=args.latency_ms, jitter_ms=args.jitter_ms, drop=args.drop, dup=args.dup,
        reorder=args.reorder, seed=args.seed,
        compensate_latency=not args.no_latency_compensation) if links else {}
    try:
        plan = build_plan(slow=args.slow_robot, rates=args.robot_rate, kill=args.kill_robot,
                          stop=args.stop_robot, restart=args.restart_robot, **link_flags)
        plan.check([r.id for r in scenario.robots])
    except FaultSpecError as exc:
        raise BadInput(str(exc)) from None
    for rid, timing in plan.timing.items():
        hz = timing.control_rate_hz
        if args.mode == "lockstep" and hz is not None and abs(50.0 / hz - round(50.0 / hz)) > 1e-9:
            raise BadInput(f"--robot-rate {rid}:{hz:g}: in lockstep the rate must divide 50 Hz")
    return plan if plan.active else None




def make_dir(path: Path, flag: str = "--out") -> Path:
    """Create `path` (and its parents) for output; a one-line `BadInput` if it cannot be."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise BadInput(f"{flag}: cannot write to {path}: {exc.strerror or exc}") from None
    return path


def add_tls_args(p: argparse.ArgumentParser) -> None:
    """``--insecure`` and ``--tls-ca``: the transport's security of a distributed run."""
    p.add_argument("--insecure", action="store_true",
                   help="plain TCP: no TLS, no access control (default: mutual TLS with a "
                        "per-run CA in <out>/tls and the run's access control on the world)")
    p.add_argument("--tls-ca", metavar="DIR",
                   help="sign the run's certificates with the CA in DIR (ca.pem, ca.key) "
                        "instead of a fresh per-run CA")


def tls_ca(args: argparse.Namespace) -> Path | None:
    """The ``--tls-ca`` directory, checked (`BadInput` if unusable or with ``--insecure``)."""
    if not getattr(args, "tls_ca", None):
        return None
    if getattr(args, "insecure", False):
        raise BadInput("--tls-ca and --insecure exclude each other")
    from agent.security import PkiError, RunCA

    ca = Path(args.tls_ca)
    missing = [n for n in ("ca.pem", "ca.key") if not (ca / n).is_file()]
    if missing:
        raise BadInput(f"--tls-ca {ca}: missing {', '.join(missing)}")
    try:
        RunCA.load(ca, "check")  # unreadable, not PEM, encrypted, not EC: say so now
    except PkiError as exc:
        raise BadInput(str(exc)) from None
    return ca
