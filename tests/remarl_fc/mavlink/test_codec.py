"""The sans-IO codec: framing, robustness, signing, and the named numbers."""

from __future__ import annotations

import base64
import os

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as dialect

from remarl_fc.errors import SigningKeyError
from remarl_fc.mavlink import consts
from remarl_fc.mavlink.codec import Codec, SigningConfig, load_signing_key


def heartbeat(codec: Codec) -> bytes:
    return codec.encode(codec.factory.heartbeat_encode(2, 3, 81, 4, 3))


def test_round_trip_and_sequence_numbers():
    a, b = Codec(3, 1), Codec(255, 190)
    frames = [heartbeat(a) for _ in range(3)]
    msgs = [b.decode(f, "a")[0] for f in frames]
    assert [m.get_seq() for m in msgs] == [0, 1, 2]
    assert msgs[0].get_srcSystem() == 3 and msgs[0].custom_mode == 4


def test_a_frame_split_across_datagrams_is_reassembled_per_peer():
    a, b = Codec(3, 1), Codec(255, 190)
    frame = heartbeat(a)
    assert b.decode(frame[:5], "p1") == []
    assert b.decode(heartbeat(a), "p2")  # another peer's traffic does not disturb p1
    (m,) = b.decode(frame[5:], "p1")
    assert m.get_type() == "HEARTBEAT"


@given(st.binary(max_size=300))
def test_garbage_never_raises(data):
    b = Codec(255, 190)
    out = b.decode(data, "x")
    assert isinstance(out, list)


def test_corrupt_crc_is_counted_and_dropped():
    a, b = Codec(3, 1), Codec(255, 190)
    frame = bytearray(heartbeat(a))
    frame[-1] ^= 0xFF
    assert b.decode(bytes(frame), "x") == []
    assert b.stats.bad_frames == 1
    assert b.stats.bad_frames == sum(b.stats.reasons.values())  # the total of the reasons


def test_signing_accepts_signed_and_rejects_unsigned_except_allowed():
    key = os.urandom(32)
    vehicle = Codec(1, 1, signing=SigningConfig(key, allow_unsigned=frozenset({0})))
    signed_gcs = Codec(255, 190, signing=SigningConfig(key))
    plain_gcs = Codec(254, 190)
    cmd = plain_gcs.factory.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert vehicle.decode(plain_gcs.encode(cmd), "plain") == []
    assert vehicle.stats.rejected_unsigned == 1
    assert [m.get_type() for m in vehicle.decode(heartbeat(plain_gcs), "plain")] == ["HEARTBEAT"]
    cmd = signed_gcs.factory.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    (m,) = vehicle.decode(signed_gcs.encode(cmd), "signed")
    assert m.get_type() == "COMMAND_LONG" and m.get_signed()
    wrong = Codec(253, 190, signing=SigningConfig(os.urandom(32)))
    cmd = wrong.factory.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert vehicle.decode(wrong.encode(cmd), "wrong") == []


@pytest.mark.parametrize("form", ["raw", "hex", "b64", "px4"])
def test_signing_key_file_forms(tmp_path, form):
    key = os.urandom(32)
    content = {
        "raw": key,
        "hex": key.hex().encode() + b"\n",
        "b64": base64.b64encode(key),
        "px4": key + (123).to_bytes(8, "little"),
    }[form]
    path = tmp_path / "key"
    path.write_bytes(content)
    assert load_signing_key(path) == key


def test_bad_signing_key_files(tmp_path):
    with pytest.raises(SigningKeyError, match="cannot read"):
        load_signing_key(tmp_path / "missing")
    (tmp_path / "short").write_bytes(b"abc")
    with pytest.raises(SigningKeyError, match="32-byte key"):
        load_signing_key(tmp_path / "short")


def test_named_numbers_match_the_dialect():
    for enum, prefix in [
        (consts.MsgId, "MAVLINK_MSG_ID_"),
        (consts.MavCmd, "MAV_CMD_"),
        (consts.MavResult, "MAV_RESULT_"),
        (consts.MavModeFlag, "MAV_MODE_FLAG_"),
        (consts.MavState, "MAV_STATE_"),
        (consts.MavFrame, "MAV_FRAME_"),
        (consts.EkfFlag, "EKF_"),
        (consts.AdsbFlag, "ADSB_FLAGS_"),
        (consts.LandedState, "MAV_LANDED_STATE_"),
        (consts.CopterMode, "COPTER_MODE_"),
    ]:
        for member in enum:
            assert getattr(dialect, prefix + member.name) == member.value, (prefix, member)
    for bit in consts.TypeMask:
        name = "POSITION_TARGET_TYPEMASK_" + bit.name
        assert getattr(dialect, name) == bit.value
    assert consts.TYPE_MASK_VELOCITY_YAW == 2503


def test_a_stray_start_byte_in_a_datagram_does_not_swallow_the_next_ones():
    a, b = Codec(3, 1), Codec(255, 190)
    assert b.decode(heartbeat(a) + b"\xfd", "u", datagram=True)  # the frame, then junk
    assert [m.get_type() for m in b.decode(heartbeat(a), "u", datagram=True)] == ["HEARTBEAT"]
    assert b.stats.bad_frames == 1


@settings(max_examples=300, deadline=None)
@given(
    chunks=st.lists(
        st.one_of(
            st.binary(max_size=80),  # garbage, including stray start bytes
            st.integers(0, 40).map(lambda cut: ("truncated", cut)),
            st.just(("whole", 0)),
        ),
        max_size=12,
    )
)
def test_random_and_truncated_frames_on_a_stream_never_raise_nor_hide_later_frames(chunks):
    """Garbage and cut frames may cost the frames they touch, never a frame that follows
    after a clean gap: a whole frame after 280 bytes of nothing-like-a-start is decoded."""
    a, b = Codec(3, 1), Codec(255, 190)
    for chunk in chunks:
        if isinstance(chunk, tuple):
            kind, cut = chunk
            frame = heartbeat(a)
            data = frame if kind == "whole" else frame[: min(cut, len(frame) - 1)]
        else:
            data = chunk
        for msg in b.decode(data, "stream"):
            assert msg.get_type() != "BAD_DATA"
    # a clean gap longer than any frame flushes whatever the parser holds
    b.decode(b"\x00" * 280, "stream")
    (m,) = b.decode(heartbeat(a), "stream")
    assert m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 3


@settings(max_examples=200, deadline=None)
@given(data=st.binary(max_size=600), cut=st.integers(0, 600))
def test_datagrams_of_random_bytes_with_a_frame_inside(data, cut):
    """A datagram holds whole frames: garbage around one never raises, and never yields a
    message that was not sent."""
    a, b = Codec(3, 1), Codec(255, 190)
    frame = heartbeat(a)
    datagram = data[:cut] + frame + data[cut:]
    for msg in b.decode(datagram, "peer", datagram=True):
        assert msg.get_type() != "BAD_DATA"
    # the next datagram from the same peer is decoded as if nothing had happened
    (m,) = b.decode(heartbeat(a), "peer", datagram=True)
    assert m.get_type() == "HEARTBEAT"
