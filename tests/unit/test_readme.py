"""The README's Commands section and flag tables against the argparse definitions, and its
claim about `.ci/run`: so that they cannot drift apart."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from orchestrator.cli import COMMANDS, build_parser
from orchestrator.cli.common import add_fault_args

REPO = Path(__file__).resolve().parents[2]
README = (REPO / "README.md").read_text(encoding="utf-8")
COMMANDS_SECTION = README[README.index("## Commands"):README.index("## What a run leaves")]


def long_flags(parser: argparse.ArgumentParser) -> set[str]:
    """Every long option of `parser` and of its subcommands, less --help and hidden ones."""
    out: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                out |= long_flags(sub)
        if action.help != argparse.SUPPRESS:
            out |= {o for o in action.option_strings if o.startswith("--") and o != "--help"}
    return out


def subparsers() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions
                  if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def fault_flags() -> set[str]:
    parser = argparse.ArgumentParser()
    add_fault_args(parser)
    return long_flags(parser)


def command_lines() -> list[str]:
    block = re.search(r"```sh\n(.*?)```", COMMANDS_SECTION, re.S)
    assert block, "no sh block in the README's Commands section"
    return [" ".join(shlex.split(line, comments=True)) for line in block.group(1).splitlines()
            if line.strip().startswith("orchestrator ")]


def table_rows() -> dict[str, str]:
    """Subcommand -> its flags cell, from the Commands section's table."""
    rows = re.findall(r"^\| `([a-z]+)[^`]*`[^|]*\|(.*)\|$", COMMANDS_SECTION, re.M)
    return {cmd: cell for cmd, cell in rows}


@pytest.mark.parametrize("line", command_lines())
def test_every_command_of_the_commands_section_parses(line: str) -> None:
    argv = shlex.split(line)[1:]
    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"README: `{line}` does not parse (exit {exc.code})")


def test_the_commands_section_shows_every_subcommand_and_how_to_reach_it() -> None:
    shown = {shlex.split(line)[1] for line in command_lines()}
    assert set(COMMANDS) - {"compose"} <= shown, set(COMMANDS) - shown
    # `orchestrator` is on PATH only inside the venv: the section says so.
    assert ". .venv/bin/activate" in COMMANDS_SECTION


@pytest.mark.parametrize("command", sorted(set(COMMANDS) - {"list"}))
def test_the_flag_table_lists_exactly_the_parsers_flags(command: str) -> None:
    rows = table_rows()
    assert command in rows, f"README flag table: no row for `{command}`"
    cell = rows[command]
    documented = set(re.findall(r"--[a-z0-9-]+", cell))
    if "fault flags" in cell:
        documented |= fault_flags()
    actual = long_flags(subparsers()[command])
    assert not actual - documented, f"`{command}` flags missing from the README table"
    assert not documented - actual, f"README lists flags `{command}` does not have"


def test_the_fault_flags_paragraph_lists_exactly_the_fault_flags() -> None:
    para = COMMANDS_SECTION[COMMANDS_SECTION.index("Fault flags"):]
    para = para[:para.index("\n\n")]
    assert set(re.findall(r"--[a-z0-9-]+", para)) == fault_flags()


def test_the_readme_test_command_is_what_ci_runs() -> None:
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8").replace(" --quiet", "")
    m = re.search(r"Run the tests.*?```sh\n(.*?)```", README, re.S)
    assert m, "no test command in the README"
    for step in m.group(1).strip().split(" && "):
        step = step.strip()
        assert step in ci, f".ci/run does not run the README's `{step}`"
    # What CI adds, the README says.
    intro = README[m.start():m.start() + 600]
    for extra in ("rm -rf .venv", "--upgrade pip", "EIFP_DOCKER_BUILD=1", "HYPOTHESIS_PROFILE=ci"):
        assert extra in ci and extra in intro, extra
