"""Pre-encoded message templates (and the packed chunk message index) give the same bytes as the generic encoders
they stand in for."""
from __future__ import annotations

import math

import hypothesis.strategies as st
import pytest
from hypothesis import given

from cosim.recording import proto
from cosim.recording.encode import planar_transform_msg, scalars_json, stamp, to_json
from cosim.recording.templates import PlanarTransform, ScalarsTemplate, marker_json, timestamp_field

T_NS = st.integers(min_value=0, max_value=2**62)
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True)
FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(T_NS)
def test_timestamp_field_is_the_encoded_timestamp(t_ns):
    assert timestamp_field(t_ns) == proto.encode("foxglove.FrameTransform", {"timestamp": stamp(t_ns)})


@given(T_NS, FINITE, FINITE, st.floats(min_value=-10.0, max_value=10.0))
def test_planar_transform_is_the_encoded_message(t_ns, x, y, yaw):
    want = proto.encode("foxglove.FrameTransform", planar_transform_msg(t_ns, "world", "cart", x, y, yaw))
    assert PlanarTransform("world", "cart").encode(timestamp_field(t_ns), x, y, yaw) == want


@given(T_NS, st.integers(min_value=0, max_value=10**9),
       st.tuples(ANY_FLOAT, st.integers(min_value=-2**63, max_value=2**63 - 1), ANY_FLOAT, ANY_FLOAT))
def test_scalars_template_is_scalars_json(t_ns, frame, values):
    names = ("t_s", "count", "x_m", "info_m")  # "info" holds "inf": non-finite values are found by position
    assert ScalarsTemplate(names, "fiff").encode(t_ns, frame, values) == scalars_json(t_ns, frame,
                                                                                        dict(zip(names, values)))


@pytest.mark.parametrize("names,kinds", [(("t_s", "frame", "x_m"), "fif"), (("frame", "y"), "ff"),
                                         (("timestamp", "x"), "ff")], ids=["frame-field", "float-frame", "fallback"])
def test_fields_named_like_the_message_keys(names, kinds):
    """A struct field ``frame`` replaces the message's frame in place (the dict merge of scalars_json)."""
    values = tuple(float(i) + 0.5 if k == "f" else 40 + i for i, k in enumerate(kinds))
    got = ScalarsTemplate(names, kinds).encode(123_456_789_012, 7, values)
    assert got == scalars_json(123_456_789_012, 7, dict(zip(names, values)))


@given(T_NS, st.integers(min_value=0, max_value=10**9), FINITE)
def test_marker_json_is_to_json(t_ns, frame, t_s):
    assert marker_json(t_ns, frame, t_s) == to_json({"timestamp": stamp(t_ns), "frame": frame, "t_s": t_s})


def test_non_finite_values_become_null():
    got = ScalarsTemplate(("a", "b", "c"), "fff").encode(0, 1, (math.nan, math.inf, -math.inf))
    assert got == b'{"timestamp":{"sec":0,"nsec":0},"frame":1,"a":null,"b":null,"c":null}'


@given(st.integers(min_value=1, max_value=2**16 - 1),
       st.lists(st.tuples(T_NS, st.integers(min_value=0, max_value=2**40)), max_size=50))
def test_message_index_record_is_mcaps(channel_id, index):
    """The chunk's MessageIndex records, packed in one call, are the bytes mcap's own record writer makes."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import MessageIndex

    from cosim.recording.mcapfile import message_index_record

    rb = RecordBuilder()
    MessageIndex(channel_id=channel_id, records=index).write(rb)
    assert message_index_record(channel_id, index) == rb.end()
