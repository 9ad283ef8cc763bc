"""Every equation reference in the code and the documents uses the paper's numbering.

`PAPER_EQUATIONS` is the Methodology section of *Forecast-Driven MPC for Decentralized
Multi-Robot Collision Avoidance* (arXiv:2508.08264): its 22 numbered ``equation``
environments, in the order they appear (none is unnumbered, ``aligned`` blocks are one
number each). A reference is ``Eq. N``, ``Eq. (N)``, ``Eqs. N-M``, ``Eqs. (N)-(M)``,
``Eqs. N and M``, ``equation (N)``, a bare ``(N)-(M)``, a row of docs/method.md's table of
equations, or ``eqN`` in a test's name. Each must name a number of the table; where a known
concept (TCPA, the threat test, the inflated radius, the cost, ...) stands just before it
(or, in the table, in the row's next cell), the number must be one the paper gives that
concept. So the same concept cannot be cited with two numbers.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

PAPER_EQUATIONS: dict[int, str] = {
    1: "unicycle model x_{k+1} = f(x_k, u_k)",
    2: "input bounds v_k, omega_k",
    3: "relative position r and velocity v_rel",
    4: "TCPA",
    5: "DCPA",
    6: "threat test DCPA <= D_thresh, 0 < TCPA < T_max",
    7: "threat ranking, argsort of TCPA",
    8: "inflated radius L and distance Q",
    9: "bearing alpha and angular offset theta",
    10: "tangent point S1 (alpha - theta, RIGHT)",
    11: "tangent point S2 (alpha + theta, LEFT)",
    12: "parametric line in (x, y, t)",
    13: "velocity cone",
    14: "line and cone: quadratic in lambda (lambda*)",
    15: "via-point cost J",
    16: "normalised path length l_i",
    17: "angular misalignment phi_ij",
    18: "argmin of J",
    19: "cubic spline p(t)",
    20: "MPC model: the unicycle",
    21: "MPC cost J",
    22: "MPC input bounds",
}

PAPER_BLOCKS: dict[tuple[int, int], str] = {
    (1, 22): "the whole method",
    (3, 7): "collision prediction (a subsection)",
    (3, 5): "relative motion, TCPA and DCPA",
    (4, 5): "TCPA and DCPA",
    (6, 7): "threat test and ranking",
    (6, 22): "from the threat test on: everything a robot decides",
    (8, 14): "via-point planning (a subsection)",
    (8, 11): "the tangent construction, L to S2",
    (9, 11): "the tangent points, alpha and theta included",
    (10, 11): "the two tangent points",
    (9, 14): "the candidates: tangent points met by the cone",
    (12, 14): "velocity cone and line intersection (a subsubsection)",
    (15, 18): "cost-based selection (a subsubsection)",
    (15, 17): "the cost J and its terms",
    (19, 22): "smoothing and MPC tracking (a subsection)",
    (20, 22): "the MPC",
}
"""The ranges a reference may cite (``Eqs. N-M``): parts of the paper that belong together.
The numbering this test replaced was one lower in places, and its ranges (7-13, 14-16, ...)
cut across these."""

_ONE = range(1, 23)
CONCEPTS: tuple[tuple[str, frozenset[int]], ...] = tuple(
    (pattern, frozenset(numbers)) for pattern, numbers in (
        (r"unicycle|roll-?out|rolled out|Jacobians|\barc\b", (1, 20)),
        (r"limits|bounds|omega_max", (2, 22)),
        (r"\bv_rel\b|\bv_r\b", (3,)),
        (r"(?i:\btcpa\b|\bdcpa\b)", (3, 4, 5)),
        (r"threats?", (6, 7)),
        (r"threat test|D_thresh|T_max", (6,)),
        (r"ranked by TCPA|sorted by TCPA|TCPA ranking|imminent first|rank(ed|ing)?", (7,)),
        (r"inflated radi(us|i)|inflated|Q <= L|\bL\b|d_safety|safety margin", (8,)),
        (r"tangent points?|tangents?|candidates", (9, 10, 11, 12, 13, 14)),
        (r"alpha - theta|\bS1\b", (10,)),
        (r"alpha \+ theta|\bS2\b", (11,)),
        (r"\bcone\b|quadratic", (12, 13, 14)),
        (r"lambda\*|λ\*", (14,)),
        (r"predicted path|\bcost\b|\bJ(_i)?\b|\bw_[jgda]\b|linearity|\bd_ij\b", (15,)),
        (r"normali[sz]ed length|\bl_i\b|\beps\b", (16,)),
        (r"angular misalignment|\bphi(_ij)?\b|φ(_ij)?", (17,)),
        (r"argmin", (18,)),
        (r"spline", (19,)),
        (r"paper's J|cost J|MPC cost|\bMPC\b|tracker|prediction model", (20, 21, 22)),
    ))
"""(regex, the paper's numbers for it): the concept nearest before a reference decides.
Within a pattern the longer alternatives come first (a regex takes the first that matches)."""

_NUMBER = r"\(?(\d+)\)?"
_MORE = r"(?:\s*(?:-|–|,|and|to)\s*\(?\d+\)?)*"
REFERENCE = re.compile(
    rf"\b(?:Eqs?\.?|[Ee]quations?)\s*~?{_NUMBER}{_MORE}"  # Eq. 7, Eqs. (3)-(5), equation (6)
    rf"|\((\d+)\)\s*[-–]\s*\(\d+\)"                     # a bare (15)-(17)
    rf"|(?:\b|(?<=_))eq(\d+)(?:_and_eq\d+)*")            # eq6 in a test's name
TABLE_ROW = re.compile(r"^\| ((?:\(\d+\)\s*[-–,]?\s*)+) \| ([^|]*) \|", re.M)
CONTEXT_CHARS = 80


@dataclass(frozen=True)
class Reference:
    """One reference: the numbers it names and the text that says what it is about."""

    line: int
    text: str
    numbers: tuple[int, ...]
    ranges: tuple[tuple[int, int], ...]
    context: str
    after: bool = False
    """The context follows the reference (a table row) instead of preceding it."""


def numbers_of(text: str) -> tuple[int, ...]:
    """The equation numbers `text` names: ranges expanded, lists kept."""
    found = [int(n) for n in re.findall(r"\d+", text)]
    out: list[int] = []
    for i, n in enumerate(found):
        out.append(n)
        between = text[text.find(str(found[i - 1])) + len(str(found[i - 1])):] if i else ""
        if i and re.match(r"\)?\s*(?:-|–|to)\s*\(?$", between[: between.find(str(n))]):
            out.extend(range(found[i - 1] + 1, n))
    return tuple(sorted(set(out)))


def ranges_of(text: str) -> tuple[tuple[int, int], ...]:
    """The ``N-M`` ranges in `text` (``Eqs. (9)–(11)`` -> ((9, 11),))."""
    return tuple((int(a), int(b)) for a, b in
                 re.findall(r"(\d+)\)?\s*(?:-|–|to)\s*\(?(\d+)", text))


def context_before(text: str, start: int, previous_end: int) -> str:
    """What the text says just before `start`: the rest of a table row or of a line of code
    with a trailing comment; else the comment block or the paragraph it is in (never past
    a blank line, a docstring's quotes or the previous reference), at most `CONTEXT_CHARS`.
    After a formula, ``X = ... (Eq. N)``, only what is left of the ``=``: the reference
    numbers X."""
    line_start = text.rfind("\n", 0, start) + 1
    line = text[line_start:start].lstrip()
    if line.startswith("|") or ("#" in line and not line.startswith("#")):
        begin = line_start
    else:
        begin = line_start
        comment = line.startswith("#")
        while begin > 0:
            prev_start = text.rfind("\n", 0, begin - 1) + 1
            prev = text[prev_start:begin - 1].strip()
            if not prev or prev.startswith("|") or comment != prev.startswith("#"):
                break
            if '"""' in prev:
                begin = prev_start + text[prev_start:begin].rfind('"""') + 3
                break
            begin = prev_start
    raw = text[max(begin, previous_end, start - CONTEXT_CHARS):start]
    if '"""' in raw:
        raw = raw[raw.rfind('"""') + 3:]
    context = re.sub(r"\s*#\s*|\s+", " ", raw)
    if " = " in context and re.search(r"(?:[)|\]^\d]\s*|\S\s{3,})\(?$", raw):
        context = context.rsplit(" = ", 1)[0]
    return context


def references(text: str) -> list[Reference]:
    """Every equation reference in `text`, with the text before it (or its table row's)."""
    refs = []
    previous_end = 0
    for m in REFERENCE.finditer(text):
        context = context_before(text, m.start(), previous_end)
        if m.group(0).startswith("eq"):  # a test's name: test_..._threats_by_eq6
            context = context.rsplit("def ", 1)[-1].replace("_", " ")
        refs.append(Reference(text.count("\n", 0, m.start()) + 1, m.group(0),
                              numbers_of(m.group(0)), ranges_of(m.group(0)), context))
        previous_end = m.end()
    for m in TABLE_ROW.finditer(text):
        refs.append(Reference(text.count("\n", 0, m.start()) + 1, m.group(1).strip(),
                              numbers_of(m.group(1)), ranges_of(m.group(1)), m.group(2),
                              after=True))
    return refs


def concept(ref: Reference) -> tuple[str, frozenset[int]] | None:
    """The concept nearest to the reference in its context (the longest of those that end
    nearest, or for a table row start first), or None."""
    best: tuple[tuple[int, int], str, frozenset[int]] | None = None
    for pattern, numbers in CONCEPTS:
        for m in re.finditer(pattern, ref.context):
            distance = m.start() if ref.after else len(ref.context) - m.end()
            key = (distance, -(m.end() - m.start()))
            if best is None or key < best[0]:
                best = (key, m.group(0), numbers)
    return None if best is None else (best[1], best[2])


def problems(text: str) -> list[str]:
    """What is wrong with the equation references in `text`."""
    out = []
    for ref in references(text):
        unknown = [n for n in ref.numbers if n not in PAPER_EQUATIONS]
        if unknown or not ref.numbers:
            out.append(f"line {ref.line}: {ref.text!r} names no equation of the paper "
                       f"{unknown or ''}")
            continue
        for block in ref.ranges:
            if block not in PAPER_BLOCKS:
                out.append(f"line {ref.line}: {ref.text!r}: {block[0]}-{block[1]} is not a "
                           "part of the paper (`PAPER_BLOCKS`)")
        near = concept(ref)
        if near is not None and not set(ref.numbers) & near[1]:
            out.append(f"line {ref.line}: {ref.text!r} next to {near[0]!r}, which the paper "
                       f"numbers {sorted(near[1])}")
    return out


def sources() -> list[Path]:
    """The code (product and tests) and the documents."""
    code = [p for top in ("agent", "world", "orchestrator", "eifp_wire", "scripts", "tests")
            for p in sorted((REPO / top).rglob("*.py")) if p != Path(__file__).resolve()]
    return [*code, *sorted((REPO / "docs").glob("*.md")), REPO / "README.md"]


@pytest.mark.parametrize("source", sources(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_equation_reference_uses_the_papers_numbers(source: Path) -> None:
    found = problems(source.read_text(encoding="utf-8"))
    assert not found, f"{source.relative_to(REPO)}:\n" + "\n".join(found)


def test_the_table_is_the_papers_22_equations() -> None:
    assert sorted(PAPER_EQUATIONS) == list(_ONE)
    assert all(a < b and {a, b} <= set(PAPER_EQUATIONS) for a, b in PAPER_BLOCKS)
    # every concept's numbers are equations of the table
    assert all(numbers <= set(PAPER_EQUATIONS) for _, numbers in CONCEPTS)


def test_method_md_maps_every_equation_to_code() -> None:
    text = (REPO / "docs" / "method.md").read_text(encoding="utf-8")
    rows = [ref for ref in references(text) if ref.after]
    assert {n for ref in rows for n in ref.numbers} == set(PAPER_EQUATIONS)


@pytest.mark.parametrize(("text", "numbers"), [
    ("Eq. 7", (7,)), ("Eq. (7)", (7,)), ("Eqs. 3-5", (3, 4, 5)), ("Eqs. (9)–(11)", (9, 10, 11)),
    ("Eqs. 15 and 17", (15, 17)), ("(15)-(17)", (15, 16, 17)), ("(1),(20)", (1, 20)),
    ("eq10_and_eq11", (10, 11)),
])
def test_numbers_of_each_form(text: str, numbers: tuple[int, ...]) -> None:
    assert numbers_of(text) == numbers


@pytest.mark.parametrize("wrong", [
    # the numbering this test replaced: one lower from the threat test on
    "applies the threat test of Eq. (5)",
    "t_max_s: T_max of Eq. (5) [s].",
    "Indices of the others that are threats (Eq. 6), ranked by TCPA (Eq. 6).",
    "L = r_robot + r_obstacle + d_safety (Eq. 7).",
    "LEFT is the tangent at alpha + theta (Eq. 10)",
    "a candidate reached after more than T_max (lambda*, Eq. 13) is",
    "J_i = w_g l_i + w_d sum_j w_j / d_ij + w_a sum_j w_j phi_ij            (Eq. 14)",
    "eps of Eq. (15) [m].",
    "the cost of Eqs. 12-14",
    "tangents to inflated discs, filtered by the velocity cone (Eqs. 7-13).",
    "the raw candidates (Eqs. 8-10).",
    "the interaction-aware cost of Eqs. (14)-(16).",
    "| (7) | normalised length | same |",
    "def test_inflated_radius_is_the_sum_eq7():",
    "the paper's Eq. 23",
])
def test_a_wrong_number_is_found(wrong: str) -> None:
    assert problems(wrong), wrong


@pytest.mark.parametrize("right", [
    "applies the threat test of Eq. (6) and the ranking of Eq. (7)",
    "Indices of the others that are threats (Eq. 6), ranked by TCPA (Eq. 7).",
    "LEFT is the tangent at alpha + theta (Eq. 11): the robot turns. RIGHT is alpha - theta "
    "(Eq. 10).",
    "TCPA and DCPA at the measured velocities (Eqs. 4-5).",
    "| (7) | TCPA ranking | `agent.planning.threats.ranked` |",
    "def test_paper_config_declares_threats_by_eq6_alone():",
])
def test_a_right_number_passes(right: str) -> None:
    assert not problems(right), problems(right)
