"""The line protocol's written rules (docs/mill-protocol.md) and properties of the framing (issue 27).

CRC vectors: CRC-16/CCITT-FALSE is the CRC that Python's ``binascii.crc_hqx`` computes
with init 0xFFFF, an implementation independent of ours; the catalogue's check value of
"123456789" is 0x29B1 and of the empty message the init value 0xFFFF.
"""

from __future__ import annotations

import binascii

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from control import protocol as p


@pytest.mark.parametrize(
    ("data", "crc"), [(b"", 0xFFFF), (b"123456789", 0x29B1), (b"A", 0xB915), (b"\x00" * 4, 0x84C0)]
)
def test_crc16_published_vectors(data, crc):
    assert p.crc16(data) == crc
    assert binascii.crc_hqx(data, 0xFFFF) == crc


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=80))
def test_crc16_matches_an_independent_implementation(data):
    assert p.crc16(data) == binascii.crc_hqx(data, 0xFFFF)


def _frame_with_crc_text(body: bytes, crc_txt: bytes) -> bytes:
    return b"$" + body + b"*" + crc_txt


def test_crc_hex_must_be_upper_case():
    body = b"5,STA"
    crc = f"{p.crc16(body):04X}"
    assert any(c.isalpha() for c in crc), crc  # the test needs a letter in the CRC
    good = p.decode_line(_frame_with_crc_text(body, crc.encode()))
    assert good == p.Frame(5, "STA", ())
    bad = p.decode_line(_frame_with_crc_text(body, crc.lower().encode()))
    assert isinstance(bad, p.BadFrame) and bad.reason == "syntax" and bad.seq == 5


def test_command_must_be_upper_case():
    body = b"5,sta"
    line = _frame_with_crc_text(body, f"{p.crc16(body):04X}".encode())
    out = p.decode_line(line)
    assert isinstance(out, p.BadFrame) and out.reason == "syntax"


def test_crlf_terminated_frames_and_stray_cr_are_accepted():
    """``\\n`` ends a frame and ``\\r`` is ignored anywhere (CRLF from a terminal program works)."""
    line = p.encode_frame(77, p.SET, 12.5)
    assert line.endswith(b"\n")
    crlf = line[:-1] + b"\r\n"
    mid = line[:4] + b"\r" + line[4:]
    out = p.FrameDecoder().feed(crlf + mid)
    assert out == [p.Frame(77, "SET", ("12.50",))] * 2
    # a bare \r does not end a frame: the next $ starts a new one and the first is unterminated
    out = p.FrameDecoder().feed(line[:-1] + b"\r" + line)
    assert [type(o) for o in out] == [p.BadFrame, p.Frame]


def test_a_frame_of_exactly_max_line_bytes_is_valid_and_one_more_is_not():
    # "$12345,SET" (10) + ",<16>,<16>,<13>" (48) + "*CRC\n" (6) = 64 bytes
    args = ["1" * 16, "2" * 16, "3" * 13]
    enc = p.encode_frame(12345, p.SET, *args)
    assert len(enc) == p.MAX_LINE
    assert p.FrameDecoder().feed(enc) == [p.Frame(12345, "SET", tuple(args))]
    with pytest.raises(p.ControlError):
        p.encode_frame(12345, p.SET, *args[:2], "3" * 14)
    # the decoder refuses a 65-byte line even with a valid CRC
    body = b"12345,SET," + b",".join(a.encode() for a in [*args[:2], "3" * 14])
    line = b"$" + body + f"*{p.crc16(body):04X}\n".encode()
    assert len(line) == p.MAX_LINE + 1
    out = p.FrameDecoder().feed(line)
    assert len(out) == 1 and isinstance(out[0], p.BadFrame) and out[0].reason == "too_long"


_ARG = st.text(alphabet="0123456789ABCDEFabcdef.+-", min_size=1, max_size=6)


@settings(max_examples=300, deadline=None)
@given(
    seq=st.integers(0, p.SEQ_MOD - 1),
    cmd=st.sampled_from([*p.HOST_COMMANDS, p.ACK, p.NAK]),
    args=st.lists(_ARG, max_size=4),
)
def test_encode_decode_round_trip(seq, cmd, args):
    try:
        line = p.encode_frame(seq, cmd, *args)
    except p.ControlError:
        return  # longer than MAX_LINE: refused, never sent
    assert len(line) <= p.MAX_LINE
    assert p.FrameDecoder().feed(line) == [p.Frame(seq, cmd, tuple(args))]


@settings(max_examples=300, deadline=None)
@given(garbage=st.binary(max_size=200), seq=st.integers(0, p.SEQ_MOD - 1))
def test_decoder_never_raises_and_recovers_after_any_garbage(garbage, seq):
    """Whatever comes first, a valid frame after a newline is decoded (``$`` resynchronises)."""
    dec = p.FrameDecoder()
    out = dec.feed(garbage)
    assert all(isinstance(o, (p.Frame, p.BadFrame)) for o in out)
    frame = p.encode_frame(seq, p.STA)
    out = dec.feed(b"\n" + frame)
    assert out[-1] == p.Frame(seq, "STA", ())
