"""`orchestrator list`: the setups, scenario families, planners and modes."""

from __future__ import annotations

import argparse

from agent.core.config import PLANNER_NAMES
from agent.process import ExitCode


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("list", help="setups, families and planners")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from orchestrator.analysis.report import format_table
    from orchestrator.experiments.families import FAMILIES, SCALABLE_SETUPS, SETUPS, setup_path
    from world.scenario_file import load_scenario

    rows = []
    for name in SETUPS:
        s = load_scenario(setup_path(name))
        scal = "--agents" if name in SCALABLE_SETUPS else "fixed"
        rows.append([name, len(s.robots), scal, s.description])
    print("Setups (the paper's A-G, orchestrator/setups/*.yaml):")
    print(format_table(["name", "robots", "size", "description"], rows))
    print("\nFamilies (sized with --agents N, seeded with --seed):")
    print(format_table(["name", "default N", "what"],
                       [[k, n, what] for k, (n, what) in FAMILIES.items()]))
    print("\nPlanners (--planner):")
    for p in PLANNER_NAMES:
        print(f"  {p}")
    print("\nModes (--mode): distributed (default: one process per robot over Zenoh), "
          "lockstep (one deterministic process)")
    return ExitCode.OK
