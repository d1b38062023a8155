"""Frame slots: the shared-memory copies through which the sink hands frames to the recorder process."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.recording.slots import NOT_PUT, FrameSlots
from shm_schema import (
    ArrayBlock,
    Field,
    Schema,
    SchemaMismatch,
    Segment,
    StructBlock,
    image_block,
)

NAMES = ("dyn", "img", "pts")


def run_schema(h: int = 6) -> Schema:
    return Schema([StructBlock("dyn", "dynamics", (Field("t_s", "s"), Field("frame", "", "i8"), Field("x_m", "m"))),
                   image_block("img", "renderer", h, 5), ArrayBlock("pts", "perception", "f4", (7, 4)),
                   ArrayBlock("other", "perception", "f4", (3,))], ["dynamics", "renderer", "perception"])


def fill(seg: Segment, frame: int, which=NAMES) -> None:
    if "dyn" in which:
        with seg.write("dyn", frame) as v:
            v.t_s, v.frame, v.x_m = 0.1 * frame, frame, float("nan") if frame == 0 else -2.5 * frame
    if "img" in which:
        with seg.write("img", frame) as img:
            img[...] = (np.arange(img.size).reshape(img.shape) + frame) % 256
    if "pts" in which:
        with seg.write("pts", frame) as p:
            p[...] = np.arange(28, dtype=np.float32).reshape(7, 4) * frame


def test_put_copies_each_block_into_its_slot_and_reads_back(shm_clean):
    run = Segment.local(run_schema())
    slots = FrameSlots.create(run.schema, NAMES, 2)
    try:
        reader = FrameSlots.attach(slots.name, run.schema, NAMES, 2)
        fill(run, 4)
        assert slots.put(run, 1, 4, NAMES) == NAMES
        fill(run, 5)  # the run moves on: the slot keeps frame 4
        frame, (structs, arrays, stamps) = reader.frame(1)
        assert frame == 4 and stamps == {"dyn": 4, "img": 4, "pts": 4}
        assert structs["dyn"] == {"t_s": 0.4, "frame": 4, "x_m": -10.0}
        np.testing.assert_array_equal(arrays["pts"], np.arange(28, dtype=np.float32).reshape(7, 4) * 4)
        assert arrays["img"].shape == (6, 5, 4) and arrays["img"][0, 0, 0] == 4
        assert np.shares_memory(arrays["img"], reader.view(1, "img")), "the recorder reads the slot in place"
        assert reader.stamp(1, "pts") == 4
        assert slots.put(run, 0, 5, ("dyn",)) == ("dyn",)
        frame0, (structs0, arrays0, stamps0) = reader.frame(0)
        assert frame0 == 5 and structs0["dyn"]["frame"] == 5 and arrays0 == {} and stamps0 == {"dyn": 5}
        assert reader.frame(1)[1].structs["dyn"]["frame"] == 4 and reader.stamp(0, "img") == NOT_PUT
        reader.close()
    finally:
        slots.close()
        slots.unlink()


def test_put_keeps_each_blocks_own_stamp(shm_clean):
    """A block that lags the sink call (perception one frame behind) keeps its stamp in the slot."""
    run = Segment.local(run_schema())
    with FrameSlots.create(run.schema, NAMES, 1) as slots:
        try:
            fill(run, 6, ("dyn", "img"))
            fill(run, 5, ("pts",))
            assert slots.put(run, 0, 6, NAMES) == NAMES
            frame, (_, arrays, stamps) = slots.frame(0)
            assert frame == 6 and stamps == {"dyn": 6, "img": 6, "pts": 5} and slots.stamp(0, "pts") == 5
            np.testing.assert_array_equal(arrays["pts"], np.arange(28, dtype=np.float32).reshape(7, 4) * 5)
        finally:
            slots.unlink()


def test_blocks_never_written_are_not_copied(shm_clean):
    run = Segment.local(run_schema())
    with FrameSlots.create(run.schema, NAMES, 1) as slots:
        try:
            fill(run, 0, which=("dyn",))
            assert slots.put(run, 0, 0, NAMES) == ("dyn",)
            _, (structs, arrays, _) = slots.frame(0)
            assert np.isnan(structs["dyn"]["x_m"]) and arrays == {}
        finally:
            slots.unlink()


def test_attach_refuses_other_slot_layouts(shm_clean):
    run = Segment.local(run_schema())
    slots = FrameSlots.create(run.schema, NAMES, 2)
    try:
        with pytest.raises(SchemaMismatch):
            FrameSlots.attach(slots.name, run_schema(h=7), NAMES, 2)
        with pytest.raises(SchemaMismatch):
            FrameSlots.attach(slots.name, run.schema, NAMES, 3)
        with pytest.raises(ValueError, match="at least one frame slot"):
            FrameSlots.create(run.schema, NAMES, 0)
    finally:
        slots.close()
        slots.unlink()


def test_slot_count_fits_the_byte_budget():
    from cosim.recording import RecordOptions
    from cosim.recording.sink import MAX_SLOTS, MIN_SLOTS, QUEUE_BYTES, slot_count

    assert slot_count(RecordOptions(), 3_300_000) == QUEUE_BYTES // 3_300_000 == 20  # a default GL frame
    assert slot_count(RecordOptions(), 8_000) == MAX_SLOTS  # a ground-truth frame
    assert slot_count(RecordOptions(), 10**9) == MIN_SLOTS
    assert slot_count(RecordOptions(queue_frames=3), 8_000) == 3 and slot_count(RecordOptions(queue_frames=0), 1) == 0
