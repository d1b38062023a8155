"""The supervisor's recorder: struct rows at their stamps, final arrays of the last completed frame."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.runtime.recorder import FRAME_COPY_LIMIT, Recorder
from shm_schema import ArrayBlock, Field, Schema, Segment, StructBlock

#: rows of the large test array: float32 (LARGE_ROWS, 100) is larger than FRAME_COPY_LIMIT
LARGE_ROWS = FRAME_COPY_LIMIT // 400 + 8


def make_segment() -> Segment:
    return Segment.local(Schema([
        StructBlock("state", "w", [Field("t_s", "s"), Field("k", "", "i8")]),
        ArrayBlock("small", "w", "float32", (6, 3), unit="m"),
        ArrayBlock("large", "w", "float32", (LARGE_ROWS, 100), unit="m"),
    ], ["w", "supervisor"]))


def write_frame(seg: Segment, frame: int) -> None:
    with seg.write("state", frame) as v:
        v.t_s, v.k = 0.1 * frame, frame
    for name in ("small", "large"):
        with seg.write(name, frame) as a:
            a[...] = frame


def test_the_large_array_is_beyond_the_per_frame_copy():
    assert make_segment().schema.layout["large"].block.nbytes > FRAME_COPY_LIMIT


def test_final_arrays_are_the_last_completed_frame():
    seg = make_segment()
    rec = Recorder(seg, ("w",))
    for frame in range(3):
        write_frame(seg, frame)
        rec.record(frame)
    rec.finish()
    assert rec.array_frames == {"small": 2, "large": 2}
    assert np.all(rec.arrays["small"] == 2) and np.all(rec.arrays["large"] == 2)
    assert not np.shares_memory(rec.arrays["large"], seg.view("large"))
    np.testing.assert_array_equal(rec.series()["state.k"], [0, 1, 2])


@pytest.mark.parametrize("fails_inside", [False, True])
def test_a_write_after_the_last_completed_frame_is_not_taken(fails_inside):
    """A writer that writes (or fails while writing) in the frame after the last completed one: the small arrays
    keep the completed frame's copy, the large ones are left out rather than taken from the wrong frame."""
    seg = make_segment()
    rec = Recorder(seg, ("w",))
    for frame in range(2):
        write_frame(seg, frame)
        rec.record(frame)
    if fails_inside:
        with pytest.raises(RuntimeError, match="writer failed"):
            with seg.write("large", 2) as a:
                a[: len(a) // 2] = 7.0
                raise RuntimeError("writer failed")
    else:
        write_frame(seg, 2)
    rec.finish()
    assert rec.array_frames["small"] == 1 and np.all(rec.arrays["small"] == 1)
    assert rec.array_frames["large"] == -1 and not rec.arrays["large"].any()


def test_struct_rows_go_to_their_stamps_and_repeat_when_not_rewritten():
    seg = make_segment()
    rec = Recorder(seg, ("w",))
    write_frame(seg, 0)
    rec.record(0)
    rec.record(1)                      # nothing rewritten: frame 1 repeats frame 0's row
    write_frame(seg, 2)
    rec.record(2)
    np.testing.assert_array_equal(rec.series()["state.k"], [0, 0, 2])
