"""Every test a docstring, a comment or a document points at exists: ``tests/...`` paths named
in the product code (its docstrings and comments included), in docs/*.md and in README.md,
and the test function of a ``tests/x.py::test_name`` reference."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PRODUCT = ("eifp_wire", "agent", "world", "orchestrator", "scripts")
TEST_PATH = re.compile(r"(?<![\w/.-])tests(?:/[\w.*-]+)*(?:::\w+)?")
"""``tests``, ``tests/unit/``, ``tests/x/test_y.py``, ``tests/x/test_*.py``,
``tests/x/test_y.py::test_z``."""


def sources() -> list[Path]:
    """The product's modules and the documents that may name tests."""
    files = [p for pkg in PRODUCT for p in sorted((REPO / pkg).rglob("*.py"))]
    return [*files, *sorted((REPO / "docs").glob("*.md")), REPO / "README.md"]


def named_test_paths(text: str) -> set[str]:
    """Every ``tests/...`` reference in `text`, without trailing punctuation."""
    return {m.group(0).rstrip(".,;:") for m in TEST_PATH.finditer(text)}


def missing(reference: str) -> str | None:
    """Why `reference` (a path, a glob, or ``path::test_name``) names nothing, or None."""
    path, _, test_name = reference.partition("::")
    if "*" in path:
        return None if list(REPO.glob(path)) else "matches no file"
    if not (REPO / path).exists():
        return "no such file or directory"
    if test_name and not re.search(rf"^\s*(async )?def {test_name}\(",
                                   (REPO / path).read_text(encoding="utf-8"), re.M):
        return f"{path} has no test {test_name}"
    return None


@pytest.mark.parametrize("source", sources(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_named_test_exists(source: Path) -> None:
    text = source.read_text(encoding="utf-8")
    broken = {ref: why for ref in sorted(named_test_paths(text)) if (why := missing(ref))}
    assert not broken, f"{source.relative_to(REPO)} names tests that do not exist: {broken}"


def test_the_checker_reads_every_form_of_reference() -> None:
    text = ("tested in tests/agent/test_ifp.py. See `tests/unit/test_architecture.py::"
            "test_no_import_cycles`, tests/unit/eifp_wire/test_*.py and (tests/system).")
    refs = named_test_paths(text)
    assert refs == {"tests/agent/test_ifp.py",
                    "tests/unit/test_architecture.py::test_no_import_cycles",
                    "tests/unit/eifp_wire/test_*.py", "tests/system"}
    assert missing("tests/agent/test_ifp.py") == "no such file or directory"
    assert missing("tests/unit/test_architecture.py::test_no_import_cycles") is None
    assert missing("tests/unit/test_architecture.py::test_nothing") is not None
    assert missing("tests/unit/eifp_wire/test_*.py") is None
    assert missing("tests/unit/eifp_wire/test_nothing_*.py") == "matches no file"
