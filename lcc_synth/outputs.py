"""Output files of the commands: safe names, exclusive and atomic writes, checks before the work.

Every file a command writes goes through this module, so that a run never loses a user's data
and never writes outside its output directory:

* **Names from a problem file** (the problem, a layout, a scenario, a controller) become part
  of a path only through :func:`path_part` (``[A-Za-z0-9_.-]``, never ``.`` or ``..``), and
  :func:`child` refuses a name that would leave its directory.
* **Atomic, exclusive publication.** A file is written under a temporary name in its own
  directory (``.NAME.part-PID-RANDOM.EXT``) and published when it is complete
  (:func:`publish`): ``os.link`` to the final name, which fails when that name exists (an
  exclusive create, with no window between a check and the write), then the temporary name
  is removed. When the name is taken, the next free one (``NAME-2.EXT``, ``NAME-3.EXT``...) is
  used and returned, so two runs started in the same second never share a file. With
  ``overwrite`` (the commands' ``--overwrite``) ``os.replace`` publishes over an existing
  file, atomically. A reader sees no file or the whole file, never half of one.
* **Checks before the work** (:func:`check_file`, :func:`check_directory`): the directory
  exists or can be created, a probe file can be created in it (not ``os.access``: root passes
  every mode check, a read-only mount does not), an explicit path that exists is refused
  without ``overwrite``, and the free space covers the estimated size with
  :data:`SPACE_MARGIN`. These are :class:`~lcc_synth.errors.ConfigError` naming the flag.
* **Errors while writing** (a disk that fills during the run) are one
  :class:`~lcc_synth.errors.FileError` naming the path; the temporary file is removed.

Results directories (``results/<problem>-<UTC>/``) are created with ``mkdir`` (exclusive:
:func:`new_directory`), filled through :func:`write_text` / :func:`writing`, and removed by
:func:`remove_if_empty` when a run stops before writing anything into them.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from lcc_synth.errors import ConfigError, FileError

__all__ = [
    "SPACE_MARGIN",
    "SPACE_FLOOR",
    "path_part",
    "child",
    "free_bytes",
    "check_directory",
    "check_file",
    "temporary_path",
    "publish",
    "Pending",
    "writing",
    "write_text",
    "new_directory",
    "remove_if_empty",
]

#: Free space a check asks for: the estimated size times this, plus :data:`SPACE_FLOOR`.
SPACE_MARGIN = 1.25
#: Bytes a check keeps free beyond the estimate (file-system metadata, logs of other programs).
SPACE_FLOOR = 1 << 20

_BAD = re.compile(r"[^A-Za-z0-9_.\-]")


def path_part(name: object, field: str = "name") -> str:
    """``name`` as one safe part of a file name: characters outside ``[A-Za-z0-9_.-]`` become
    ``_``, and so does a leading dot (no hidden files, no ``..``); an empty name or one of dots
    only is refused.

    Examples
    --------
    >>> path_part("x/../../../victim"), path_part("../names"), path_part("h2 (robust)")
    ('x_.._.._.._victim', '_._names', 'h2__robust_')
    """
    text = str(name).strip()
    if not text or set(text) <= {"."}:
        raise ConfigError(field, f"cannot be used in a file name: {name!r}")
    cleaned = _BAD.sub("_", text)
    return "_" + cleaned[1:] if cleaned.startswith(".") else cleaned


def child(directory: str | Path, name: str) -> Path:
    """``directory / name`` for a file name made of :func:`path_part` pieces; refuses a name
    with a path separator or one that resolves outside ``directory``.

    Raises
    ------
    ConfigError
        Field ``name``: not a plain file name, or one that leaves ``directory``.
    FileError
        ``directory / name`` is a symbolic link pointing outside ``directory`` (e.g. planted
        in an ``--export DIR``): it is never written through; the error names the link and
        comes, like a full disk, after the work (exit 1, the results still printed).
    """
    directory = Path(directory)
    if not name or os.sep in name or (os.altsep and os.altsep in name) or name in (".", ".."):
        raise ConfigError("name", f"not a plain file name: {name!r}")
    path = directory / name
    if path.resolve().parent != directory.resolve():
        if path.is_symlink():  # a link in the directory, found when the file is written
            raise FileError(path, f"is a symbolic link to {os.readlink(path)}, outside "
                            f"{directory}: remove the link or write to another directory")
        raise ConfigError("name", f"{name!r} would be written outside {directory}")
    return path


def _existing_ancestor(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def free_bytes(path: str | Path) -> int:
    """Free bytes (for this user) on the file system that holds ``path`` (or would hold it:
    its nearest existing ancestor)."""
    return int(shutil.disk_usage(_existing_ancestor(Path(path))).free)


def _probe(directory: Path) -> str | None:
    """Why ``directory`` cannot take a new file (``None`` if it can): creates and removes a
    probe file, which tests what the write will meet (mode bits, read-only mounts, ACLs)."""
    probe = directory / f".lcc-synth-probe-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as err:
        return err.strerror or str(err)
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:  # pragma: no cover - created but not removable: still writable
        pass
    return None


def check_directory(path: str | Path, flag: str, size: float = 0, what: str = "") -> Path:
    """Check, before the work, that files of ``size`` bytes in total can be written in the
    directory ``path`` (which may not exist yet: its nearest existing ancestor is checked).

    Raises
    ------
    ConfigError
        For ``flag``: a file in the way, a directory that cannot be written, or less free space
        than ``size * SPACE_MARGIN + SPACE_FLOOR`` (``what`` says what the estimate counts).
    """
    path = Path(path)
    anc = _existing_ancestor(path)
    if not anc.is_dir():
        raise ConfigError(flag, f"{anc} is not a directory (needed for {path})")
    why = _probe(anc)
    if why is not None:
        where = f"{anc}" if anc == path.absolute() else f"{anc} (to create {path})"
        raise ConfigError(flag, f"cannot write in {where}: {why}")
    need = float(size) * SPACE_MARGIN + SPACE_FLOOR if size else 0.0
    if need:
        free = free_bytes(anc)
        if free < need:
            from lcc_synth.resources import format_bytes

            raise ConfigError(
                flag,
                f"{path} is on a file system with {format_bytes(free)} free; the run will "
                f"write about {format_bytes(size)}{f' ({what})' if what else ''}: free space "
                "or write elsewhere",
            )
    return path


def check_file(
    path: str | Path, flag: str, overwrite: bool = False, size: float = 0, what: str = ""
) -> Path:
    """Check, before the work, that the explicit output file ``path`` (``--rrd``, ``--png``,
    ``--out``) can be written: not a directory, not an existing file unless ``overwrite``, a
    writable directory with room for ``size`` bytes (:func:`check_directory`)."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(flag, f"is a directory, expected a file path: {str(path)!r}")
    if path.exists() and not overwrite:
        raise ConfigError(
            flag, f"{path} exists: pass --overwrite to replace it, or choose another path"
        )
    check_directory(path.parent, flag, size, what)
    return path


def temporary_path(path: str | Path) -> Path:
    """A private temporary name next to ``path`` with the same extension (so that writers
    which infer the format from it, e.g. matplotlib, still do)."""
    path = Path(path)
    tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    return path.with_name(f".{path.stem}.part-{tag}{path.suffix}")


def _numbered(path: Path, k: int) -> Path:
    return path if k == 1 else path.with_name(f"{path.stem}-{k}{path.suffix}")


def publish(tmp: str | Path, path: str | Path, overwrite: bool = False) -> Path:
    """Give the complete file ``tmp`` its final name and return that name.

    Without ``overwrite`` the name is taken exclusively (``os.link``; ``NAME-2``, ``NAME-3``...
    when it exists, so nothing is ever replaced); with it, ``os.replace`` puts the file over
    ``path`` atomically. ``tmp`` is gone afterwards.
    """
    tmp, path = Path(tmp), Path(path)
    try:
        if overwrite:
            os.replace(tmp, path)
            return path
        for k in range(1, 10_000):
            target = _numbered(path, k)
            try:
                os.link(tmp, target)
            except FileExistsError:
                continue
            except OSError as err:  # no hard links here (some FUSE / FAT file systems)
                if err.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
                    raise
                try:  # exclusive placeholder, then replace it (empty for an instant)
                    os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
                except FileExistsError:
                    continue
                os.replace(tmp, target)
                return target
            os.unlink(tmp)
            return target
        raise FileError(path, "no free name (NAME-2 .. NAME-9999 all exist)")
    except OSError as err:
        if isinstance(err, FileError):
            raise
        raise FileError.from_os(path, err) from None


@dataclass
class Pending:
    """A file being written: ``tmp`` while it is written, ``path`` its final name (set to the
    name actually used once :func:`writing` publishes it)."""

    tmp: Path
    path: Path


@contextmanager
def writing(path: str | Path, overwrite: bool = False) -> Iterator[Pending]:
    """Write a file atomically: yields a :class:`Pending` whose ``tmp`` the caller writes;
    on success it is published (:func:`publish`) and ``pending.path`` is the name used; on
    any error the temporary file is removed and an ``OSError`` becomes a
    :class:`~lcc_synth.errors.FileError` naming ``path``."""
    path = Path(path)
    pending = Pending(temporary_path(path), path)
    try:
        yield pending
        pending.path = publish(pending.tmp, path, overwrite)
    except OSError as err:
        _discard(pending.tmp)
        if isinstance(err, FileError):
            raise
        raise FileError.from_os(path, err) from None
    except BaseException:
        _discard(pending.tmp)
        raise


def _discard(tmp: Path) -> None:
    try:
        tmp.unlink()
    except OSError:
        pass


def write_text(path: str | Path, text: str, overwrite: bool = False) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`writing`); returns the name used."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FileError.from_os(path.parent, err, "create") from None
    with writing(path, overwrite) as out:
        with open(out.tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return out.path


def new_directory(root: str | Path, name: str, stamp: str, flag: str = "--out") -> Path:
    """A new directory ``root/<name>-<stamp>`` created exclusively (``-2``, ``-3``... when the
    name exists, e.g. two runs in the same second); ``name`` goes through :func:`path_part`."""
    base = Path(root) / f"{path_part(name)}-{stamp}"
    path, k = base, 1
    while True:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.mkdir(exist_ok=False)
            return path
        except FileExistsError:
            k += 1
            path = base.with_name(f"{base.name}-{k}")
        except OSError as err:
            raise ConfigError(flag, f"cannot create {str(path)!r}: {err.strerror or err}") from None


def remove_if_empty(directory: str | Path | None) -> bool:
    """Remove ``directory`` if it exists and holds nothing (a run that stopped before writing
    into it); returns whether it was removed."""
    if directory is None:
        return False
    try:
        Path(directory).rmdir()  # fails on a non-empty directory: what we want
        return True
    except OSError:
        return False
