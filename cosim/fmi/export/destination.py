"""Where ``export-fmu --out`` writes, checked before anything is built, and the write itself, atomic.

The rules are ``run``'s for ``--out`` (docs/reliability.md), for a file:

* ``--out NAME.fmu`` names the file; ``--out FOLDER`` (an existing folder) writes ``FOLDER/<scenario name>.fmu``,
  and the file written is the one printed;
* the folder it goes in must exist (``--parents`` makes the missing ones) and be writable;
* an existing FMU there is replaced only with ``--overwrite``; a file that is not an FMU (not a zip archive with a
  ``modelDescription.xml``) is never replaced, ``--overwrite`` or not, and neither is anything but a regular file;
* the FMU is written to a hidden temporary file beside it and renamed over it (``os.replace``), so that a full
  disk or a killed export leaves the earlier file (or none), never a truncated one.

Every path in a message is shown with :func:`shown`, so that a control character in ``--out`` (an escape typed
into the terminal) never reaches it raw.
"""
from __future__ import annotations

import os
import shutil
import zipfile
from pathlib import Path

from cosim.errors import shown_path as shown
from cosim.runtime.files import atomic_replace

__all__ = ["DestinationError", "FMU_SUFFIX", "shown", "fmu_destination", "write_atomically"]

#: the suffix of an FMU file
FMU_SUFFIX = ".fmu"


class DestinationError(ValueError):
    """``--out`` cannot take the FMU; the message names the path (escaped) and what to do."""


def _is_fmu(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as zf:
            return "modelDescription.xml" in zf.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def fmu_destination(out: str | os.PathLike, name: str, *, overwrite: bool = False, parents: bool = False) -> Path:
    """The file ``--out`` ``out`` names for the FMU of scenario ``name``, checked as the module docstring says (the
    missing folders made with ``parents``); raises :class:`DestinationError`."""
    out = Path(out)
    if out.is_dir():
        out = out / f"{name}{FMU_SUFFIX}"
    if out.suffix.lower() != FMU_SUFFIX:
        raise DestinationError(f"--out {shown(out)}: an FMU file's name ends in {FMU_SUFFIX} (or give an existing "
                               "folder to write <scenario name>.fmu into)")
    folder = out.parent
    if not folder.is_dir():
        if folder.exists():
            raise DestinationError(f"--out {shown(out)}: {shown(folder)} is not a folder")
        if not parents:
            raise DestinationError(f"--out {shown(out)}: its folder {shown(folder)} does not exist; create it, or "
                                   "add --parents to create every missing folder")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DestinationError(f"--out {shown(out)}: cannot create {shown(folder)}: {exc.strerror or exc}") \
                from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise DestinationError(f"--out {shown(out)}: permission denied (the folder {shown(folder)} is not writable)")
    if out.exists() or out.is_symlink():
        if out.is_symlink() or not out.is_file():
            raise DestinationError(f"--out {shown(out)}: exists and is not a regular file; choose another --out")
        if not _is_fmu(out):
            raise DestinationError(f"--out {shown(out)}: holds a file that is not an FMU, which export never "
                                   "replaces; choose another --out")
        if not overwrite:
            raise DestinationError(f"--out {shown(out)}: holds an FMU; choose another --out, or add --overwrite to "
                                   "replace it")
    return out


def write_atomically(built: Path, out: Path) -> None:
    """Copy the file ``built`` to ``out`` through a temporary file beside it and ``os.replace``
    (cosim.runtime.files.atomic_replace); on any error the temporary file is removed and ``out`` is as it was
    (:class:`cosim.errors.OutputError`, naming ``out``, is raised)."""
    with atomic_replace(out) as tmp:
        shutil.copyfile(built, tmp)
