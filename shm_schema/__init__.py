"""Declared shared-memory layout of a run: blocks, derived layout and fingerprint, the segment itself."""
from .layout import ALIGN, Schema
from .segment import Phase, SchemaMismatch, Segment, SegmentNotFound, SnapshotTimeout, StructView
from .spec import ArrayBlock, Block, Field, SchemaError, StructBlock, image_block

__all__ = [
    "ALIGN", "Schema", "Phase", "SchemaMismatch", "Segment", "SegmentNotFound", "SnapshotTimeout", "StructView",
    "ArrayBlock", "Block", "Field", "SchemaError", "StructBlock", "image_block",
]
