"""Block declarations: the only place a shared-memory layout is written.

Three kinds of block, each with exactly one writer process:

* :class:`StructBlock` - named scalars (float64 or int64), each with a unit; viewed as attributes.
* :class:`ArrayBlock` - one fixed-shape array of any numeric dtype.
* :func:`image_block` - an (H, W, 4) uint8 array (an ArrayBlock with ``kind="image"``).

Sizes, offsets, the fingerprint and the numpy views are derived from these records (``shm_schema.layout``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Field", "StructBlock", "ArrayBlock", "image_block", "Block", "SchemaError", "check_name"]

_NAME = re.compile(r"^[a-z][a-z0-9_]{0,47}$")
_STRUCT_DTYPES = ("f8", "i8")


class SchemaError(ValueError):
    """A block declaration is malformed (bad name, dtype, shape, duplicate, ...)."""


def check_name(kind: str, name: str) -> str:
    """Return ``name`` if it is a valid identifier for ``kind``, else raise :class:`SchemaError`."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise SchemaError(f"{kind} name {name!r} must match {_NAME.pattern}")
    return name


@dataclass(frozen=True)
class Field:
    """One scalar of a struct block. ``dtype`` is ``"f8"`` (float64) or ``"i8"`` (int64)."""

    name: str
    unit: str = ""
    dtype: str = "f8"
    doc: str = ""

    def __post_init__(self) -> None:
        check_name("field", self.name)
        if self.dtype not in _STRUCT_DTYPES:
            raise SchemaError(f"field {self.name!r}: dtype {self.dtype!r} not in {_STRUCT_DTYPES}")


@dataclass(frozen=True)
class StructBlock:
    """A record of named scalars written by one process."""

    name: str
    writer: str
    fields: tuple[Field, ...]
    doc: str = ""
    kind: str = field(default="struct", init=False)

    def __post_init__(self) -> None:
        check_name("block", self.name)
        check_name("writer", self.writer)
        object.__setattr__(self, "fields", tuple(self.fields))
        if not self.fields:
            raise SchemaError(f"struct block {self.name!r} has no fields")
        names = [f.name for f in self.fields]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise SchemaError(f"struct block {self.name!r} repeats fields {sorted(dup)}")

    @property
    def dtype(self) -> np.dtype:
        """Packed structured dtype of the record."""
        return np.dtype([(f.name, "<" + f.dtype) for f in self.fields])

    @property
    def nbytes(self) -> int:
        return self.dtype.itemsize


@dataclass(frozen=True)
class ArrayBlock:
    """A fixed-shape numeric array written by one process."""

    name: str
    writer: str
    dtype: str
    shape: tuple[int, ...]
    unit: str = ""
    doc: str = ""
    kind: str = "array"

    def __post_init__(self) -> None:
        check_name("block", self.name)
        check_name("writer", self.writer)
        object.__setattr__(self, "shape", tuple(int(s) for s in self.shape))
        try:
            dt = np.dtype(self.dtype)
        except TypeError as exc:
            raise SchemaError(f"array block {self.name!r}: bad dtype {self.dtype!r}") from exc
        if dt.kind not in "biuf" or dt.fields is not None:
            raise SchemaError(f"array block {self.name!r}: dtype {self.dtype!r} is not a plain numeric type")
        object.__setattr__(self, "dtype", dt.newbyteorder("<").str)
        if not self.shape or any(s < 1 for s in self.shape):
            raise SchemaError(f"array block {self.name!r}: shape {self.shape} must have positive extents")
        if self.kind not in ("array", "image"):
            raise SchemaError(f"array block {self.name!r}: kind {self.kind!r}")

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * np.dtype(self.dtype).itemsize


def image_block(name: str, writer: str, height: int, width: int, doc: str = "") -> ArrayBlock:
    """An (height, width, 4) uint8 image block (RGBA8, row 0 at the top of the image)."""
    return ArrayBlock(name, writer, "u1", (height, width, 4), unit="", doc=doc, kind="image")


Block = StructBlock | ArrayBlock
