"""Pure framing: CRC, encode/decode, the incremental decoder against garbage."""

from __future__ import annotations

import random

import pytest

from control import protocol as p
from control.errors import ControlError


def test_crc16_ccitt_false_check_value():
    # the standard check value of CRC-16/CCITT-FALSE
    assert p.crc16(b"123456789") == 0x29B1


def test_encode_decode_roundtrip():
    line = p.encode_frame(42, p.SET, 12.5)
    assert line.startswith(b"$42,SET,12.50*") and line.endswith(b"\n")
    f = p.decode_line(line[:-1])
    assert f == p.Frame(42, "SET", ("12.50",))
    st = p.MillStatus(12.5, 11.25, True, "WDOG")
    f = p.decode_line(p.encode_frame(7, p.ACK, *p.status_args(st))[:-1])
    assert isinstance(f, p.Frame) and p.parse_status(f.args) == st


def test_encode_rejects_invalid():
    with pytest.raises(ControlError):
        p.encode_frame(70000, p.STA)
    with pytest.raises(ControlError):
        p.encode_frame(1, "set")
    with pytest.raises(ControlError):
        p.encode_frame(1, p.SET, float("nan"))
    with pytest.raises(ControlError):
        p.encode_frame(1, p.SET, "a" * 40)


def test_every_single_byte_corruption_is_detected():
    line = p.encode_frame(123, p.SET, 20.0)[:-1]
    for i in range(len(line)):
        for x in range(1, 256):
            bad = bytearray(line)
            bad[i] ^= x
            out = p.FrameDecoder().feed(bytes(bad) + b"\n")
            assert all(isinstance(o, p.BadFrame) for o in out), (i, x, out)


def test_decoder_resyncs_after_garbage_and_splits_anywhere():
    frames = [p.encode_frame(i, p.SET, float(i)) for i in range(1, 6)]
    stream = b"\x00\xff junk$$$*12\n" + frames[0] + b"$1,SET*ZZ" + frames[1] + b"\r" + b"".join(frames[2:])
    rng = random.Random(1)
    dec = p.FrameDecoder()
    got = []
    i = 0
    while i < len(stream):
        n = rng.randint(1, 7)
        got += dec.feed(stream[i : i + n])
        i += n
    ok = [g for g in got if isinstance(g, p.Frame)]
    assert [f.seq for f in ok] == [1, 2, 3, 4, 5]
    assert any(isinstance(g, p.BadFrame) for g in got)


def test_over_long_line_is_reported_once_and_skipped():
    dec = p.FrameDecoder()
    out = dec.feed(b"$1,SET," + b"9" * 500 + b"\n" + p.encode_frame(2, p.STA))
    assert [type(o).__name__ for o in out] == ["BadFrame", "Frame"]
    assert out[0].reason == "too_long" and out[1].seq == 2


def test_random_bytes_never_raise_and_never_decode():
    rng = random.Random(7)
    dec = p.FrameDecoder()
    frames = 0
    for _ in range(200):
        data = bytes(rng.randrange(256) for _ in range(rng.randint(1, 300)))
        frames += sum(isinstance(o, p.Frame) for o in dec.feed(data))
    assert frames == 0


def test_bad_crc_keeps_readable_seq():
    line = bytearray(p.encode_frame(99, p.SET, 5.0)[:-1])
    line[-1] = ord("0") if line[-1] != ord("0") else ord("1")
    bad = p.decode_line(bytes(line))
    assert isinstance(bad, p.BadFrame) and bad.reason == "crc" and bad.seq == 99


def test_parse_rpm_arg():
    assert p.parse_rpm_arg("12.50") == 12.5
    for bad in ("-1", "nan", "inf", "1e3", "", "12.5.1", "0x10"):
        assert p.parse_rpm_arg(bad) is None


def test_a_status_with_numbers_no_board_can_have_is_malformed():
    """A checksum-valid status whose rpm is NaN, infinite, negative or beyond the protocol's
    five digits was taken as the board's state (the supervisor then had no rpm to ramp from
    and jumped straight to its target)."""
    assert p.parse_status(("12.50", "0.00", "1", "OK")) == p.MillStatus(12.5, 0.0, True, None)
    for sp, act in (("nan", "0.00"), ("0.00", "nan"), ("inf", "1.00"), ("-5.00", "0.00"), ("0.00", "-1.00"),
                    ("1e9", "0.00"), ("100000.00", "0.00")):
        with pytest.raises(ControlError, match="malformed mill status"):
            p.parse_status((sp, act, "1", "OK"))


def test_next_seq_wraps_and_skips_zero():
    assert p.next_seq(1) == 2
    assert p.next_seq(65535) == 1


def test_examples_in_the_protocol_doc_are_valid_frames():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "mill-protocol.md").read_text()
    lines = [ln.split(None, 1)[1] for ln in doc.splitlines() if ln.startswith(("host   $", "device $"))]
    lines = [ln.split()[0] for ln in lines if "...." not in ln]
    assert len(lines) >= 5
    for ln in lines:
        assert isinstance(p.decode_line(ln.encode()), p.Frame), ln
