"""File input and output: atomic writes, bounded reads.

A write goes to a temporary file in the target folder, then a rename: a failure
leaves neither a partial file nor a stray temporary.  A read stops at a size
limit, so a device or a huge file is refused instead of exhausting memory.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO


def _file_mode() -> int:
    """Permissions of a new file under the process umask (0644 with the usual umask 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_open(path: Path, mode: str = "w", *, newline: str | None = "") -> Iterator[IO[str]]:
    """Open ``path`` for writing so that it appears only if the block succeeds (with the umask's permissions)."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
    try:
        with os.fdopen(fd, mode, encoding="utf-8", newline=newline) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates 0600; a result file is for colleagues too
        os.chmod(tmp, _file_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_open(path, newline=None) as fh:
        fh.write(text)


def read_text_bounded(path: Path, limit: int, *, what: str = "file") -> str:
    """Read a UTF-8 text file of at most ``limit`` bytes; every failure is a one-line ``ValueError``.

    Reading stops after ``limit + 1`` bytes, so a device or a huge file
    (``/dev/zero``) is refused without exhausting memory.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise ValueError(f"{path}: the {what} is larger than {limit:,} bytes")
    if b"\x00" in data:
        raise ValueError(f"{path}: the {what} contains NUL bytes: not a text file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: the {what} is not UTF-8 text (byte {exc.start})") from None


def write_all(files: dict[Path, str | bytes]) -> None:
    """Write several files all or nothing: every one to a temporary beside it first, then all renamed.

    A failure before the renames (a full disk, a missing folder that cannot
    be made) leaves none of them and no temporaries.
    """
    temps: list[tuple[str, Path]] = []
    try:
        for path, content in files.items():
            path = Path(path)
            parent = path.parent if str(path.parent) else Path(".")
            parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
            temps.append((tmp, path))
            with os.fdopen(fd, "wb") as fh:
                fh.write(content.encode("utf-8") if isinstance(content, str) else content)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, _file_mode())
    except BaseException:
        for tmp, _ in temps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise
    for tmp, path in temps:
        os.replace(tmp, path)
