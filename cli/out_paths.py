"""Output paths, checked before any work: every command that writes a file or folder refuses an
existing output unless ``--force``, and finds a path it cannot write (a read-only folder, a
parent that is a file) at once, as a one-line :class:`serpar.errors.ConfigError` (exit 2).

Writability is probed by creating (and removing) a temporary file in the folder that will
hold the output, or in its nearest existing ancestor when folders are still to be created:
permission bits alone do not tell (root ignores them; /proc and read-only mounts refuse
anyway)."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from serpar.errors import ConfigError

FORCE_HELP = "replace an existing output (default: refuse it)"
RECORDING_FILES = ("meta.json", "signals.parquet", "signals.csv", "measurements.parquet",
                   "measurements.csv")
"""What a recording folder consists of (docs/recording.md): what --force replaces in one."""


def add_force(parser: argparse.ArgumentParser) -> None:
    """The ``--force`` flag, with one meaning on every command that writes."""
    parser.add_argument("--force", action="store_true", help=FORCE_HELP)


def _refuse(flag: str, path: Path, what: str) -> ConfigError:
    return ConfigError(f"{flag} {path}: {what}")


def _probe(flag: str, path: Path, folder: Path) -> None:
    """The output `path` can be written in `folder`, or (not there yet) be created in its
    nearest existing ancestor: that is a folder this process can write into."""
    while not folder.exists():
        if folder == folder.parent:
            break
        folder = folder.parent
    if not folder.is_dir():
        raise _refuse(flag, path, f"cannot be created: {folder} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".serpar-probe-")
    except OSError as exc:
        raise _refuse(flag, path, f"cannot write in {folder} ({exc.strerror or type(exc).__name__})") from None
    os.close(fd)
    os.unlink(probe)


def out_file(path: str | Path, flag: str, force: bool, suffix: str | None = None,
             parents: bool = True) -> Path:
    """Check an output file: refused if it exists (unless `force`) or is a folder, if it does
    not end in `suffix`, if its folder is missing (`parents` False) or cannot be written."""
    out = Path(path)
    if suffix is not None and out.suffix.lower() != suffix:
        raise _refuse(flag, out, f"the path must end in {suffix}")
    if out.is_dir():
        raise _refuse(flag, out, "is a folder; give a file path")
    if not parents and not out.parent.is_dir():
        raise _refuse(flag, out, f"folder {out.parent} does not exist")
    if out.exists() or out.is_symlink():
        if not force:
            raise _refuse(flag, out, "already exists; --force overwrites it")
        if not os.access(out, os.W_OK):
            raise _refuse(flag, out, "exists and is not writable")
    _probe(flag, out, out.parent)
    return out


def out_files(paths: Iterable[str | Path], flag: str, force: bool) -> list[Path]:
    """:func:`out_file` for files written together (one refusal names the first that exists)."""
    return [out_file(p, flag, force) for p in paths]


@dataclass(frozen=True)
class OutFolder:
    """A checked output folder; :meth:`clear` removes what a previous output left in it."""

    path: Path
    replaces: tuple[str, ...]

    def clear(self) -> None:
        """Remove the files of a previous output (just before writing the new one), so no
        stale table mixes into it; other files in the folder are left alone."""
        for name in self.replaces:
            stale = self.path / name
            if stale.is_file() or stale.is_symlink():
                stale.unlink()


def out_folder(path: str | Path, flag: str, force: bool,
               replaces: tuple[str, ...] = RECORDING_FILES) -> OutFolder:
    """Check an output folder: an existing folder that is not empty is refused (unless
    `force`), a file in its place always; the folder (or the ancestor it will be created in)
    must be writable. `replaces`: the names a previous output has in it."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise _refuse(flag, out, "exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise _refuse(flag, out, "already exists; --force replaces it")
    _probe(flag, out, out)
    return OutFolder(out, replaces)


def existing_folders(paths: Iterable[Path], flag: str, root: str | Path) -> None:
    """Refuse, in one line naming the first, the folders of `paths` that exist already."""
    there = [p for p in paths if p.exists()]
    if there:
        more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
        raise _refuse(flag, Path(root), f"{there[0]}{more} already exists; --force replaces it")
