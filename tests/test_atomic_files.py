"""One atomic-write helper (cosim.runtime.files): a writer's temporary file renamed over the target, or removed."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import OutputError
from cosim.runtime.files import atomic_replace, atomic_write

ROOT = Path(__file__).resolve().parent.parent
HELPER = ROOT / "cosim" / "runtime" / "files.py"


def test_a_writer_of_its_own_replaces_the_target_whole(tmp_path):
    path = tmp_path / "a.npz"
    path.write_bytes(b"old")
    with atomic_replace(path) as tmp, open(tmp, "wb") as f:
        assert path.read_bytes() == b"old"                       # the target is untouched while writing
        np.savez_compressed(f, x=np.arange(3))
    assert np.load(path)["x"].tolist() == [0, 1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]


def test_an_interrupted_write_leaves_the_target_and_no_temporary_file(tmp_path):
    path = tmp_path / "results.csv"
    atomic_write(path, "old\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_replace(path) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert path.read_text() == "old\n" and sorted(p.name for p in tmp_path.iterdir()) == ["results.csv"]


def test_an_os_error_names_the_target(tmp_path):
    with pytest.raises(OutputError, match="no-such-dir/x.json"):
        atomic_write(tmp_path / "no-such-dir" / "x.json", "{}")


def renames(text: str) -> list[int]:
    """Lines of ``os.replace`` / ``os.rename`` calls and of one-argument ``.replace(x)`` / ``.rename(x)`` calls (a
    path's: ``str.replace`` takes two)."""
    lines = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("replace",
                                                                                                      "rename"):
            owner = node.func.value
            if (isinstance(owner, ast.Name) and owner.id == "os") or (len(node.args) == 1 and not node.keywords):
                lines.append(node.lineno)
    return lines


def test_the_scan_finds_hand_written_renames():
    assert renames("import os\nos.replace(a, b)\ntmp.replace(path)\ns.replace('a', 'b')\nx.rename(y)\n") == [2, 3, 5]


def test_no_other_module_renames_files_by_hand():
    hand = [f"{path.relative_to(ROOT)}:{line}"
            for d in ("cosim", "shm_schema", "dynamics_proc", "renderer_proc", "perception_proc", "bench")
            for path in sorted((ROOT / d).rglob("*.py")) if path != HELPER
            for line in renames(path.read_text(encoding="utf-8"))]
    assert not hand, "write through cosim.runtime.files.atomic_write / atomic_replace:\n" + "\n".join(hand)
