"""An FMU's zip archive checked as fmpy extracts it, before anything is extracted or run.

``fmpy.extract`` unpacks the whole archive into a temporary folder when the FMU is instantiated, and refuses a
member name with a backslash, a drive letter (``:``) or a leading ``/`` by raising a plain Exception at start-up.
:func:`archive_problem` refuses those names at validation, and also what ``zipfile`` would quietly rewrite or what
another unpacker would follow out of the folder: a ``..`` component and a symbolic link. The archive's size once
unpacked and its member count are bounded (:data:`MAX_UNPACKED_BYTES`, :data:`MAX_MEMBERS`), so that a zip bomb
is refused from its directory alone.
"""
from __future__ import annotations

import os
import stat
import zipfile

__all__ = ["MAX_UNPACKED_BYTES", "MAX_MEMBERS", "MAX_DESCRIPTION_BYTES", "archive_problem"]

#: most bytes an FMU's archive may unpack to: 1 GiB, ten times the largest FMUs of the FMI cross-check set
MAX_UNPACKED_BYTES = 1 << 30
#: most members an FMU's archive may hold
MAX_MEMBERS = 10_000
#: largest modelDescription.xml read, bytes
MAX_DESCRIPTION_BYTES = 64 << 20


def _name_problem(name: str) -> str | None:
    """Why member ``name`` cannot be extracted safely, None when it can."""
    if "\\" in name:
        return "holds a backslash (fmpy refuses it: every slash must be a forward slash)"
    if ":" in name or name.startswith("/"):
        return "is absolute or names a drive (fmpy refuses it: a member path is relative to the archive)"
    if ".." in name.split("/"):
        return "climbs out of the archive with '..'"
    return None


def archive_problem(path: str | os.PathLike) -> str | None:
    """Why the zip archive at ``path`` cannot be extracted as an FMU safely (a sentence to follow the file name),
    None when it can; OSError or zipfile.BadZipFile when it cannot be read."""
    with zipfile.ZipFile(path) as zf:
        infos = zf.infolist()
    if len(infos) > MAX_MEMBERS:
        return f"is an archive of {len(infos):,} members; an FMU holds at most {MAX_MEMBERS:,}"
    total = 0
    for info in infos:
        why = _name_problem(info.filename)
        if why is not None:
            return f"has an archive member {info.filename!r} that {why}; re-export the FMU"
        if stat.S_ISLNK(info.external_attr >> 16):
            return f"has an archive member {info.filename!r} that is a symbolic link; re-export the FMU without links"
        total += info.file_size
    if total > MAX_UNPACKED_BYTES:
        return f"unpacks to {total:,} bytes; an FMU is allowed at most {MAX_UNPACKED_BYTES:,} (1 GiB)"
    description = next((i for i in infos if i.filename == "modelDescription.xml"), None)
    if description is not None and description.file_size > MAX_DESCRIPTION_BYTES:
        return f"has a modelDescription.xml of {description.file_size:,} bytes; at most {MAX_DESCRIPTION_BYTES:,}"
    return None
