"""shm_schema: derived layout, fingerprint, round trips in-process and under spawn, seqlock, attach rules."""
from __future__ import annotations

import multiprocessing as mp
import struct
from pathlib import Path

import numpy as np
import pytest

from shm_schema import (
    ALIGN,
    ArrayBlock,
    Field,
    Schema,
    SchemaError,
    SchemaMismatch,
    Segment,
    SegmentNotFound,
    StructBlock,
    image_block,
)


def make_schema(h=48, w=64, extra_field=False):
    fields = [Field("t_s", "s"), Field("x_m", "m"), Field("count", "", "i8")]
    if extra_field:
        fields.append(Field("y_m", "m"))
    return Schema([
        StructBlock("state", "writer_a", fields),
        ArrayBlock("grid", "writer_a", "float32", (7, 5), unit="m"),
        ArrayBlock("ids", "writer_b", "uint16", (3,)),
        image_block("cam0_depth", "writer_b", h, w),
    ], ["writer_a", "writer_b", "observer"])


def test_layout_is_derived_and_aligned():
    s = make_schema()
    offsets = [lay.offset for lay in s.layout.values()]
    assert offsets == sorted(offsets)
    for lay in s.layout.values():
        assert lay.offset % ALIGN == 0 and lay.data_offset % ALIGN == 0
        assert lay.data_offset == lay.offset + ALIGN
    ends = [lay.data_offset + lay.nbytes for lay in s.layout.values()]
    assert all(e <= o for e, o in zip(ends, offsets[1:]))
    assert s.layout["cam0_depth"].nbytes == 48 * 64 * 4
    assert s.layout["state"].nbytes == 24
    assert s.total_nbytes % ALIGN == 0 and s.total_nbytes >= ends[-1]


def test_fingerprint_tracks_every_declared_detail():
    a, b = make_schema(), make_schema()
    assert a.fingerprint == b.fingerprint
    assert make_schema(h=49).fingerprint != a.fingerprint
    assert make_schema(extra_field=True).fingerprint != a.fingerprint
    assert Schema.decode(a.encoded).fingerprint == a.fingerprint


@pytest.mark.parametrize("build, match", [
    (lambda: StructBlock("s", "w", []), "no fields"),
    (lambda: StructBlock("s", "w", [Field("a"), Field("a")]), "repeats fields"),
    (lambda: Field("Bad-Name"), "must match"),
    (lambda: Field("a", dtype="f4"), "dtype"),
    (lambda: ArrayBlock("a", "w", "float32", (0, 3)), "positive extents"),
    (lambda: ArrayBlock("a", "w", "U8", (3,)), "numeric"),
    (lambda: Schema([ArrayBlock("a", "w", "f4", (1,)), ArrayBlock("a", "w", "f4", (1,))], ["w"]), "twice"),
    (lambda: Schema([ArrayBlock("a", "nobody", "f4", (1,))], ["w"]), "not a participant"),
])
def test_bad_declarations_are_refused(build, match):
    with pytest.raises(SchemaError, match=match):
        build()


def test_local_round_trip_and_zero_copy_views():
    seg = Segment.local(make_schema())
    with seg.write("state", 5) as v:
        v.t_s, v.x_m, v.count = 0.5, -1.25, 42
    assert seg.frame_of("state") == 5 and seg.seq_of("state") == 2
    assert seg.view("state").as_dict() == {"t_s": 0.5, "x_m": -1.25, "count": 42}
    grid = seg.view("grid")
    grid[...] = np.arange(35, dtype=np.float32).reshape(7, 5)
    assert np.shares_memory(grid, seg.view("grid"))
    frame, copy = seg.snapshot("grid")
    assert frame == -1 and np.array_equal(copy, grid) and not np.shares_memory(copy, grid)
    with pytest.raises(AttributeError, match="no field 'nope'"):
        seg.view("state").nope = 1.0
    with pytest.raises(KeyError, match="no block 'missing'"):
        seg.view("missing")


def test_seqlock_is_odd_while_writing():
    seg = Segment.local(make_schema())
    with seg.write("grid", 1):
        assert seg.seq_of("grid") % 2 == 1
    assert seg.seq_of("grid") % 2 == 0


def _child_round_trip(name: str, fingerprint: str, q) -> None:
    seg = Segment.attach(name, expect=fingerprint)
    v = seg.view("state")
    grid = seg.view("grid")
    q.put((v.t_s, v.count, float(grid.sum()), seg.frame_of("state")))
    with seg.write("ids", 9) as ids:
        ids[:] = (7, 8, 9)
    img = seg.view("cam0_depth")
    img[10, 20] = (1, 2, 3, 255)
    seg.close()


def test_round_trip_under_spawn(shm_name, shm_clean):
    schema = make_schema()
    with Segment.create(shm_name, schema, run_id="rt") as seg:
        with seg.write("state", 3) as v:
            v.t_s, v.count = 1.5, 11
        seg.view("grid")[...] = 2.0
        ctx = mp.get_context("spawn")
        q = ctx.Queue()
        p = ctx.Process(target=_child_round_trip, args=(shm_name, schema.fingerprint, q))
        p.start()
        got = q.get(timeout=30)
        p.join(30)
        assert p.exitcode == 0
        assert got == (1.5, 11, 70.0, 3)
        assert list(seg.view("ids")) == [7, 8, 9] and seg.frame_of("ids") == 9
        assert tuple(seg.view("cam0_depth")[10, 20]) == (1, 2, 3, 255)
        # the child exited: the segment must still be there (its resource tracker did not delete it)
        assert (Path("/dev/shm") / shm_name).exists()
        again = Segment.attach(shm_name)
        assert again.view("state").count == 11
        again.close()


def test_attach_learns_layout_and_refuses_mismatch(shm_name, shm_clean):
    schema = make_schema()
    with Segment.create(shm_name, schema, run_id="fp"):
        seg = Segment.attach(shm_name)
        assert seg.schema == schema and seg.run_id == "fp"
        seg.close()
        other = make_schema(h=50)
        with pytest.raises(SchemaMismatch, match=f"fingerprint {schema.fingerprint}.*expects {other.fingerprint}"):
            Segment.attach(shm_name, expect=other)


def test_attach_missing_segment_says_so():
    with pytest.raises(SegmentNotFound, match="no run segment named 'cosimtest-nothing'"):
        Segment.attach("cosimtest-nothing")


def test_only_creator_unlinks(shm_name, shm_clean):
    with Segment.create(shm_name, make_schema()):
        seg = Segment.attach(shm_name)
        with pytest.raises(PermissionError, match="only the process that created"):
            seg.unlink()
        seg.close()


def test_error_slot_round_trip_truncates_long_tracebacks():
    seg = Segment.local(make_schema())
    seg.report_error("writer_b", 12, "ValueError", "bad", "line\n" * 10000)
    err = seg.read_error("writer_b")
    assert err["frame"] == 12 and err["type"] == "ValueError" and err["traceback"].startswith("...")
    assert seg.read_error("writer_a") is None


def test_a_failed_write_keeps_the_stamp_and_releases_the_seqlock():
    seg = Segment.local(make_schema())
    with seg.write("grid", 3) as g:
        g[...] = 1.0
    with pytest.raises(ZeroDivisionError):
        with seg.write("grid", 4):
            assert seg.seq_of("grid") == 3
            raise ZeroDivisionError
    assert seg.frame_of("grid") == 3 and seg.seq_of("grid") == 4
    assert seg.snapshot("grid")[0] == 3


def test_assign_writes_every_field_in_order_like_a_tuple():
    seg = Segment.local(make_schema())
    v = seg.view("state")
    v.assign([0.25, -3.5, 2**40 + 3])
    assert v.as_dict() == {"t_s": 0.25, "x_m": -3.5, "count": 2**40 + 3}
    ref = np.zeros((), v.array.dtype)
    ref[()] = (0.25, -3.5, 2**40 + 3)
    assert v.array.tobytes() == ref.tobytes()
    with pytest.raises(struct.error, match="integer"):
        v.assign([0.0, 0.0, 1.5])                          # no silent truncation of an integer field
