"""The product packages type-check under ``mypy --strict`` (mypy is in the dev extra).

The configuration is pyproject.toml's ``[tool.mypy]``. mypy's cache lives in pytest's cache
directory (``.pytest_cache``, git-ignored), so a second run only re-checks what changed; with
pytest's cache disabled (``-p no:cacheprovider``) it lives in this session's temporary
directory. The working tree gets no ``.mypy_cache``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ["agent", "world", "eifp_wire", "orchestrator"]


def _mypy_settings() -> dict[str, object]:
    with open(ROOT / "pyproject.toml", "rb") as f:
        settings: dict[str, object] = tomllib.load(f)["tool"]["mypy"]
    return settings


def test_the_type_check_is_strict_over_the_four_packages() -> None:
    settings = _mypy_settings()
    assert settings["strict"] is True
    files = settings["files"]
    assert isinstance(files, list) and sorted(files) == sorted(PACKAGES)
    # no switch that would silence errors wholesale
    assert not {"ignore_errors", "follow_imports"} & set(settings)


def test_mypy_strict_is_clean(request: pytest.FixtureRequest,
                              tmp_path_factory: pytest.TempPathFactory,
                              monkeypatch: pytest.MonkeyPatch) -> None:
    api = pytest.importorskip("mypy.api", reason="mypy is not installed (pip install -e '.[dev]')")
    cache = getattr(request.config, "cache", None)
    cache_dir = cache.mkdir("mypy") if cache is not None else tmp_path_factory.mktemp("mypy")
    monkeypatch.chdir(ROOT)  # `files` in the configuration are relative to the root
    stdout, stderr, status = api.run(["--config-file", str(ROOT / "pyproject.toml"),
                                      "--cache-dir", str(cache_dir)])
    assert status == 0, f"mypy --strict found errors:\n{stdout}{stderr}"
    assert stdout.startswith("Success: no issues found"), stdout
