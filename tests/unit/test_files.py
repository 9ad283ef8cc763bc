"""agent.files: run directories made for one run alone, files never written through a symlink
(issue 40, item 1)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from agent.files import (
    UnsafePathError,
    append_line,
    check_own_dir,
    create_run_dir,
    open_new,
    replace_file,
    unique_dir,
    write_new,
)
from agent.security import make_run_pki


def mode_of(path: Path) -> int:
    return stat.S_IMODE(os.lstat(path).st_mode)


def test_a_new_run_dir_is_0700_whatever_the_umask(tmp_path):
    old = os.umask(0)
    try:
        d = create_run_dir(tmp_path / "run")
    finally:
        os.umask(old)
    assert mode_of(d) == 0o700


def test_an_empty_dir_of_ours_is_taken_and_closed_to_others(tmp_path):
    d = tmp_path / "run"
    d.mkdir(mode=0o777)
    os.chmod(d, 0o777)
    assert create_run_dir(d) == d and mode_of(d) == 0o700


@pytest.mark.parametrize("make", ["non-empty", "symlink", "file"])
def test_an_existing_non_empty_dir_a_symlink_or_a_file_is_refused(tmp_path, make):
    target = tmp_path / "elsewhere"
    target.mkdir()
    d = tmp_path / "run"
    if make == "non-empty":
        d.mkdir()
        (d / "tls").mkdir()
    elif make == "symlink":
        d.symlink_to(target)
    else:
        d.write_text("x")
    with pytest.raises(UnsafePathError) as err:
        create_run_dir(d)
    assert "\n" not in str(err.value) and str(d) in str(err.value)
    assert list(target.iterdir()) == []


def test_another_users_dir_is_refused(tmp_path, monkeypatch):
    d = tmp_path / "run"
    d.mkdir()
    monkeypatch.setattr(os, "geteuid", lambda: os.stat(d).st_uid + 1)
    with pytest.raises(UnsafePathError, match="another user"):
        create_run_dir(d)
    with pytest.raises(UnsafePathError, match="another user"):
        check_own_dir(d)


def test_check_own_dir_refuses_a_dir_others_may_write(tmp_path):
    d = tmp_path / "run"
    d.mkdir()
    os.chmod(d, 0o777)
    with pytest.raises(UnsafePathError, match="writable by other users"):
        check_own_dir(d)
    os.chmod(d, 0o755)
    assert check_own_dir(d) == d


def test_unique_dir_gives_two_runs_of_one_second_two_dirs(tmp_path):
    a = unique_dir(tmp_path, "setup_d-eifp-mpc-0-20260101-000000")
    b = unique_dir(tmp_path, "setup_d-eifp-mpc-0-20260101-000000")
    assert a != b and b.name.endswith("-2") and mode_of(a) == mode_of(b) == 0o700


def test_no_writer_follows_a_planted_symlink(tmp_path):
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    d = create_run_dir(tmp_path / "run")
    for name in ("a.csv", "b.key", "c.jsonl"):
        (d / name).symlink_to(victim)
    with pytest.raises(FileExistsError):
        open_new(d / "a.csv", "w")
    with pytest.raises(FileExistsError):
        write_new(d / "b.key", b"key", file_mode=0o600)
    with pytest.raises(OSError):
        append_line(d / "c.jsonl", "line\n")
    replace_file(d / "a.csv", b"new")  # replaces the link itself
    assert victim.read_bytes() == b"precious"
    assert not (d / "a.csv").is_symlink() and (d / "a.csv").read_bytes() == b"new"


def test_a_planted_key_symlink_in_tls_is_not_followed(tmp_path):
    """The issue's attack: a pre-made RUN/tls/robot-3.key -> TARGET."""
    victim = tmp_path / "victim"
    victim.write_bytes(b"root's file")
    tls = tmp_path / "RUN" / "tls"
    tls.mkdir(parents=True)
    (tls / "robot-3.key").symlink_to(victim)
    with pytest.raises(UnsafePathError, match="not empty"):
        make_run_pki(tls, "r1", [3])
    assert victim.read_bytes() == b"root's file"


def test_new_files_get_the_mode_asked_for(tmp_path):
    d = create_run_dir(tmp_path / "run")
    write_new(d / "k.key", b"k", file_mode=0o600)
    with open_new(d / "t.csv", "w") as f:
        f.write("x")
    assert mode_of(d / "k.key") == 0o600 and mode_of(d / "t.csv") == 0o644


def test_compose_volumes_are_reused_and_their_files_replaced_never_followed(tmp_path):
    """Split certificates go into Docker volumes that may hold a previous run's files."""
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious")
    make_run_pki(tmp_path / "tls", "r1", [0], split=True)
    (tmp_path / "tls" / "robot-0" / "robot-0.key").unlink()
    (tmp_path / "tls" / "robot-0" / "robot-0.key").symlink_to(victim)
    files = make_run_pki(tmp_path / "tls", "r2", [0], split=True)
    key = Path(files["robot-0"].key)
    assert not key.is_symlink() and mode_of(key) == 0o600 and b"PRIVATE KEY" in key.read_bytes()
    assert victim.read_bytes() == b"precious"
    link = tmp_path / "tls2"
    link.symlink_to(tmp_path / "tls")
    with pytest.raises(UnsafePathError, match="symlink"):
        make_run_pki(link, "r3", [0], split=True)
