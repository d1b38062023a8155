"""Field descriptions for the JSON Schema, read from the records' attribute docstrings.

A field is described by the string literal under it::

    sensor_period_s: float = Field(default=0.1, gt=0.0, le=MAX_SENSOR_PERIOD_S)
    \"\"\"One LiDAR frame = one turn of the process ring, s.\"\"\"

The docstrings are read from the record's source (``ast``) only when a schema is generated
(:func:`schema_docs`, a ``json_schema_extra`` hook of every record), not when the records are imported: reading the
sources at import (pydantic's ``use_attribute_docstrings``) cost every process of a run ~0.3 G instructions.
"""
from __future__ import annotations

import ast
import functools
import inspect
import sys

from pydantic import BaseModel

__all__ = ["field_docs", "schema_docs"]


@functools.lru_cache(maxsize=None)
def _module_docs(module_name: str) -> dict[str, dict[str, str]]:
    """Class name -> field name -> docstring, for every class of the module's source ({} when it has none)."""
    try:
        tree = ast.parse(inspect.getsource(sys.modules[module_name]))
    except (OSError, TypeError, KeyError):
        return {}
    out: dict[str, dict[str, str]] = {}
    for node in ast.walk(tree):
        if not isinstance(node, ast.ClassDef):
            continue
        docs = out.setdefault(node.name, {})
        for stmt, after in zip(node.body, node.body[1:]):
            if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and \
                    isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant) and \
                    isinstance(after.value.value, str):
                docs[stmt.target.id] = inspect.cleandoc(after.value.value)
    return out


def field_docs(model: type[BaseModel]) -> dict[str, str]:
    """Field name -> its docstring, for ``model`` and the records it derives from."""
    docs: dict[str, str] = {}
    for cls in reversed(model.__mro__):
        if isinstance(cls, type) and issubclass(cls, BaseModel):
            docs.update(_module_docs(cls.__module__).get(cls.__qualname__, {}))
    return {name: text for name, text in docs.items() if name in model.model_fields}


def schema_docs(schema: dict, model: type[BaseModel]) -> None:
    """Describe each property of ``model``'s JSON Schema by its field's docstring (a ``Field(description=...)``
    given explicitly wins)."""
    for name, text in field_docs(model).items():
        prop = schema.get("properties", {}).get(name)
        if prop is not None:
            prop.setdefault("description", " ".join(text.split()))
