"""Run directories and the files in them, made so that nobody else can redirect them.

A run directory is created exclusively, mode 0700, by the process that owns the run; an
existing one is used only if it is a real directory (not a symlink), owned by this user and
empty (`create_run_dir`), or, for the world and the tools that write into a directory the
orchestrator made, owned by this user and writable by nobody else (`check_own_dir`). Every
file in it is created with ``O_CREAT | O_EXCL | O_NOFOLLOW`` (`open_new`): a symlink or a
file planted in its place makes the write fail instead of following it. Files that are
rewritten (``run.json``, ``metrics.json``) go through a fresh sibling and ``rename``
(`replace_file`), which replaces a planted symlink rather than writing through it.

Used by every writer of a run directory: the world's recorder, the orchestrator, the run's
certificates (`agent.security`). No zenoh, no YAML: the wire layer's scenario writer uses it
too.
"""

from __future__ import annotations

import contextlib
import os
import stat
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

NEW_FILE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
"""How every file of a run directory is opened: created here, never through a symlink."""
PRIVATE_DIR_MODE = 0o700
FILE_MODE = 0o644
PRIVATE_FILE_MODE = 0o600
MAX_NAME_TRIES = 1000
"""`unique_dir` gives up after this many taken names."""


class UnsafePathError(ValueError):
    """A run directory or file that cannot be used safely; the message is one line."""


def _why(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def create_run_dir(path: Path, *, flag: str = "--out") -> Path:
    """Create the run directory `path` exclusively, mode 0700 (its parents as usual).

    An existing `path` is accepted only if it is a directory (not a symlink), owned by this
    user and empty; it is then made 0700 before it is checked for emptiness, so nobody else
    can add an entry after the check.

    Raises:
        UnsafePathError: `path` exists and is not such a directory, or cannot be made.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UnsafePathError(f"{flag}: cannot write to {path}: {_why(exc)}") from None
    try:
        os.mkdir(path, PRIVATE_DIR_MODE)
        new = True
    except FileExistsError:
        new = False
    except OSError as exc:
        raise UnsafePathError(f"{flag}: cannot write to {path}: {_why(exc)}") from None
    with _own_dir_fd(path, flag) as fd:
        os.fchmod(fd, PRIVATE_DIR_MODE)  # whatever the umask, and before the check below
        if not new and os.listdir(fd):
            raise UnsafePathError(f"{flag}: {path} exists and is not empty; choose a new "
                                  "directory")
    return path


def check_own_dir(path: Path, *, flag: str = "--out") -> Path:
    """`path` if it is a directory (not a symlink) owned by this user that no one else may
    write into; creates it (`create_run_dir`) if it does not exist.

    Raises:
        UnsafePathError: anything else (a file, a symlink, another user's or a group- or
            world-writable directory).
    """
    path = Path(path)
    if not os.path.lexists(path):
        return create_run_dir(path, flag=flag)
    with _own_dir_fd(path, flag) as fd:
        if os.fstat(fd).st_mode & (stat.S_IWGRP | stat.S_IWOTH):
            raise UnsafePathError(f"{flag}: {path} is writable by other users; use a directory "
                                  "only you can write to")
    return path


def reuse_dir(path: Path, *, flag: str = "--out") -> Path:
    """`path` made 0700: created if it does not exist, else it must be a directory, not a
    symlink. Neither its owner nor its entries are checked: for directories handed on by
    design (compose volumes, whose files go to the container's user); write into them with
    `replace_file`, which never follows a symlink.

    Raises:
        UnsafePathError: `path` is a symlink or not a directory, or cannot be made.
    """
    path = Path(path)
    try:
        path.mkdir(mode=PRIVATE_DIR_MODE, parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        what = "is a symlink" if os.path.islink(path) else f"cannot be used: {_why(exc)}"
        raise UnsafePathError(f"{flag}: {path} {what}") from None
    try:
        os.fchmod(fd, PRIVATE_DIR_MODE)
    finally:
        os.close(fd)
    return path


@contextlib.contextmanager
def _own_dir_fd(path: Path, flag: str) -> Iterator[int]:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        what = ("is a symlink" if os.path.islink(path) else
                "is not a directory" if os.path.lexists(path) else _why(exc))
        raise UnsafePathError(f"{flag}: {path} {what}; choose a new directory") from None
    try:
        if os.fstat(fd).st_uid != os.geteuid():
            raise UnsafePathError(f"{flag}: {path} belongs to another user; choose a new "
                                  "directory")
        yield fd
    finally:
        os.close(fd)


def unique_dir(parent: Path, name: str) -> Path:
    """Create ``parent/name`` exclusively (0700), or ``name-2``, ``name-3``, ... if taken:
    two runs started in the same second get two directories.

    Raises:
        UnsafePathError: `parent` cannot be written, or `MAX_NAME_TRIES` names are taken.
    """
    parent = Path(parent)
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UnsafePathError(f"cannot write to {parent}: {_why(exc)}") from None
    for n in range(1, MAX_NAME_TRIES + 1):
        path = parent / (name if n == 1 else f"{name}-{n}")
        try:
            os.mkdir(path, PRIVATE_DIR_MODE)
        except FileExistsError:
            continue
        except OSError as exc:
            raise UnsafePathError(f"cannot write to {path}: {_why(exc)}") from None
        with _own_dir_fd(path, "--out") as fd:
            os.fchmod(fd, PRIVATE_DIR_MODE)
        return path
    raise UnsafePathError(f"{parent}: {MAX_NAME_TRIES} directories named {name}-* exist")


def open_new(path: Path | str, mode: str = "w", *, file_mode: int = FILE_MODE,
             **kwargs: Any) -> IO[Any]:
    """Open a file that must not exist yet (``O_EXCL | O_NOFOLLOW``) for writing.

    Args:
        path: the file.
        mode: ``"w"``, ``"wb"``, ``"a"`` or ``"ab"`` (as `open`; the file is new either way).
        file_mode: its permissions (0600 for keys: never readable by others, not even for a
            moment).
        kwargs: passed on to `os.fdopen` (``encoding``, ``buffering``, ...).

    Raises:
        FileExistsError: `path` exists, as a file or a symlink (followed by nothing).
    """
    if mode not in ("w", "wb", "a", "ab"):
        raise ValueError(f"open_new: mode {mode} is not a write mode")
    fd = os.open(path, NEW_FILE_FLAGS | (os.O_APPEND if mode.startswith("a") else 0), file_mode)
    try:
        os.fchmod(fd, file_mode)
        return os.fdopen(fd, mode, **kwargs)
    except BaseException:
        os.close(fd)
        raise


def write_new(path: Path | str, data: bytes, *, file_mode: int = FILE_MODE) -> Path:
    """Write `data` to a new file (`open_new`)."""
    with open_new(path, "wb", file_mode=file_mode) as f:
        f.write(data)
    return Path(path)


def append_line(path: Path | str, text: str, *, file_mode: int = FILE_MODE) -> None:
    """Append `text` to `path` (created if absent), never through a symlink."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC,
                 file_mode)
    try:
        os.write(fd, text.encode("utf-8"))
    finally:
        os.close(fd)


def replace_file(path: Path | str, data: bytes, *, file_mode: int = FILE_MODE) -> Path:
    """Write `data` to `path` atomically: a fresh sibling (`open_new`), then ``rename``.

    Readers never see half a file; a symlink at `path` is replaced, never written through.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        write_new(tmp, data, file_mode=file_mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path
