"""The line protocol's written rules (docs/mill-protocol.md) and properties of the framing (issue 27).

CRC vectors: CRC-16/CCITT-FALSE is the CRC that Python's ``binascii.crc_hqx`` computes
with init 0xFFFF, an implementation independent of ours; the catalogue's check value of
"123456789" is 0x29B1 and of the empty message the init value 0xFFFF.
"""

from __future__ import annotations

import binascii
import re

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


# --- the wire vocabulary of docs/mill-protocol.md -------------------------------------------


def test_the_wire_words_are_the_documented_ones():
    """Command, reply, NAK reason and fault strings are what the doc (and the firmware) put on the wire."""
    assert p.HOST_COMMANDS == ("SET", "RUN", "STP", "STA", "HB")
    assert (p.ACK, p.NAK) == ("ACK", "NAK")
    assert (p.NAK_CRC, p.NAK_CMD, p.NAK_ARG, p.NAK_RANGE, p.NAK_FAULT) == ("CRC", "CMD", "ARG", "RANGE", "FAULT")
    assert (p.FAULT_NONE, p.FAULT_WATCHDOG, p.FAULT_DRIVE) == ("OK", "WDOG", "DRIVE")
    assert p.READ_ONLY_COMMANDS == {"STA", "HB"}
    assert p.WATCHDOG_COMMANDS == {"SET", "RUN", "STP", "HB"}
    assert (p.MAX_LINE, p.SEQ_MOD) == (64, 65536)


@pytest.mark.parametrize(
    ("frame", "wire"),
    [
        ((17, p.SET, 20.0), b"$17,SET,20.00*96C7\n"),
        ((17, p.ACK), b"$17,ACK*FCD7\n"),
        ((18, p.STA), b"$18,STA*8F83\n"),
        ((18, p.ACK, "20.00", "19.87", "1", "OK"), b"$18,ACK,20.00,19.87,1,OK*5452\n"),
        ((19, p.NAK, p.NAK_RANGE), b"$19,NAK,RANGE*7305\n"),
    ],
)
def test_encode_frame_gives_the_docs_example_bytes(frame, wire):
    assert p.encode_frame(*frame) == wire
    args = wire[1:].split(b"*")[0].decode().split(",")[2:]
    assert p.decode_line(wire[:-1]) == p.Frame(frame[0], frame[1], tuple(args))


def test_encode_frame_argument_encoding():
    """bool -> 0/1 (never "True"), float -> two decimals, anything else -> str()."""
    assert p.encode_frame(1, p.SET, True) == _line(b"1,SET,1")
    assert p.encode_frame(1, p.SET, False) == _line(b"1,SET,0")
    assert p.encode_frame(1, p.SET, 1.5) == _line(b"1,SET,1.50")
    assert p.encode_frame(1, p.SET, 0.004) == _line(b"1,SET,0.00")
    assert p.encode_frame(1, p.SET, 7) == _line(b"1,SET,7")
    assert p.encode_frame(1, p.SET, "a-b") == _line(b"1,SET,a-b")


def _line(body: bytes) -> bytes:
    return b"$" + body + f"*{p.crc16(body):04X}\n".encode()


@pytest.mark.parametrize("seq", [0, 1, 65535])
def test_encode_frame_accepts_the_sequence_range_edges(seq):
    assert p.encode_frame(seq, p.STA) == _line(f"{seq},STA".encode())


@pytest.mark.parametrize("seq", [-1, 65536, 70000])
def test_encode_frame_refuses_a_sequence_number_outside_the_range_and_names_it(seq):
    with pytest.raises(p.ControlError, match=rf"sequence number {seq} outside 0\.\.65535"):
        p.encode_frame(seq, p.STA)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), float("-inf")])
def test_encode_frame_refuses_non_finite_numbers_and_names_them(value):
    with pytest.raises(p.ControlError, match=rf"non-finite number \({value}\)"):
        p.encode_frame(1, p.SET, value)


def test_encode_frame_error_messages_name_the_bad_body_and_the_limit():
    with pytest.raises(p.ControlError, match=r"not a valid mill frame body: b'1,set'"):
        p.encode_frame(1, "set")
    with pytest.raises(p.ControlError, match=r"not a valid mill frame body: b'1,SET,a b'"):
        p.encode_frame(1, p.SET, "a b")
    with pytest.raises(p.ControlError, match=r"longer than 64 bytes: b'\$12345,SET,1111"):
        p.encode_frame(12345, p.SET, "1" * 16, "2" * 16, "3" * 14)


# --- decode_line: the exact verdict for each kind of bad line ----------------------------


def _signed(body: bytes) -> bytes:
    """``$body*CRC`` with the right checksum (no newline: what decode_line takes)."""
    return _line(body)[:-1]


@pytest.mark.parametrize(
    ("body", "frame"),
    [
        (b"0,STA", p.Frame(0, "STA")),
        (b"65535,STA", p.Frame(65535, "STA")),
        (b"00042,HB", p.Frame(42, "HB")),
        (b"5,SET,12.50", p.Frame(5, "SET", ("12.50",))),
        (b"5,ACK,1,2,3,4,5,6", p.Frame(5, "ACK", ("1", "2", "3", "4", "5", "6"))),
        (b"5,AB," + b"x" * 16, p.Frame(5, "AB", ("x" * 16,))),
        (b"5,ABC,+-.zZ09", p.Frame(5, "ABC", ("+-.zZ09",))),
    ],
)
def test_valid_bodies_decode_to_their_frame(body, frame):
    assert p.decode_line(_signed(body)) == frame


@pytest.mark.parametrize(
    ("body", "seq"),
    [
        (b"65536,STA", None),  # one past the last sequence number: not readable
        (b"123456,STA", None),  # six digits
        (b"012345,STA", None),  # six digits, even when the number would fit
        (b"x5,STA", None),
        (b",STA", None),
        (b"5,sta", 5),  # lower-case command: syntax, the number still readable
        (b"5,S", 5),  # one letter
        (b"5,SETX", 5),  # four letters
        (b"5,STA,", 5),  # an empty argument
        (b"5,ACK,1,2,3,4,5,6,7", 5),  # seven arguments
        (b"5,SET," + b"1" * 17, 5),  # a 17-character argument
        (b"5,SET,a_b", 5),  # '_' is not an argument character
        (b"5", 5),  # no command
    ],
)
def test_checksum_valid_lines_that_break_the_grammar_are_syntax_errors(body, seq):
    raw = _signed(body)
    assert p.decode_line(raw) == p.BadFrame("syntax", raw, seq)


def test_a_wrong_checksum_is_a_crc_error_with_the_seq_when_readable():
    for body, seq in ((b"99,SET,5.00", 99), (b"0,STA", 0), (b"65535,STA", 65535), (b"65536,STA", None),
                      (b"000001,STA", None), (b"x,STA", None), (b"5,sta", 5)):
        raw = b"$" + body + f"*{p.crc16(body) ^ 1:04X}".encode()
        assert p.decode_line(raw) == p.BadFrame("crc", raw, seq), body


def test_framing_errors_are_syntax_errors_with_the_seq_when_readable():
    crc = f"{p.crc16(b'5,STA'):04X}".encode()
    cases = [
        (b"5,STA*" + crc, None),  # no '$'
        (b"$5,STA", None),  # no '*'
        (b"$5,STA*" + crc + b"*" + crc, None),  # two '*'
        (b"$5,STA*" + crc[:3], 5),  # three hex digits
        (b"$5,STA*" + crc + b"0", 5),  # five hex digits
        (b"$5,STA*", 5),  # no checksum
        (b"$5,STA*" + crc.lower(), 5),
        (b"$x,STA*" + crc.lower(), None),
    ]
    for raw, seq in cases:
        assert p.decode_line(raw) == p.BadFrame("syntax", raw, seq), raw


@pytest.mark.parametrize(("byte", "reason"), [(0x00, "binary"), (0x1F, "binary"), (0x20, "syntax"),
                                              (0x7E, "syntax"), (0x7F, "binary"), (0xFF, "binary")])
def test_the_printable_range_is_0x20_to_0x7e(byte, reason):
    """A byte outside 0x20..0x7E makes the line binary (no answer, no seq); a printable byte that
    the grammar does not allow is a syntax error (with the checksum valid and the seq readable)."""
    body = b"5,SET," + bytes([byte])
    raw = _signed(body)
    assert p.decode_line(raw) == p.BadFrame(reason, raw, 5 if reason == "syntax" else None)


def test_the_line_length_limit_counts_the_newline():
    """decode_line takes the line without its newline: 63 bytes is a full 64-byte frame, 64 is too long
    (and the verdict keeps the first MAX_LINE bytes of a longer line)."""
    ok = p.encode_frame(12345, p.SET, "1" * 16, "2" * 16, "3" * 13)[:-1]
    assert len(ok) == 63 and isinstance(p.decode_line(ok), p.Frame)
    longer = _signed(b"12345,SET," + b"1" * 16 + b"," + b"2" * 16 + b"," + b"3" * 14)
    assert len(longer) == 64
    assert p.decode_line(longer) == p.BadFrame("too_long", longer, None)
    huge = b"$" + b"\x00" * 200
    assert p.decode_line(huge) == p.BadFrame("too_long", huge[:64], None)


# --- FrameDecoder: resynchronisation, overflow, junk --------------------------------------


def test_an_unterminated_frame_is_reported_as_syntax_when_the_next_dollar_comes():
    out = p.FrameDecoder().feed(b"$1,SET,5" + p.encode_frame(2, p.STA))
    assert out == [p.BadFrame("syntax", b"$1,SET,5"), p.Frame(2, "STA")]
    assert p.FrameDecoder().feed(b"$$\n") == [p.BadFrame("syntax", b"$"), p.BadFrame("syntax", b"$")]


def test_an_over_long_frame_is_reported_once_with_its_first_max_line_bytes():
    dec = p.FrameDecoder()
    body = b"$1,SET," + b"9" * 100
    out = dec.feed(body + b"$" + b"\n")
    # reported at the 64th byte (the newline would be the 65th); the rest, up to '$', is skipped
    # silently, and the '$' starts a fresh frame (that one is the empty '$' line: syntax)
    assert out == [p.BadFrame("too_long", body[:64]), p.BadFrame("syntax", b"$")]
    out = dec.feed(body + b"\n" + b"\n" + p.encode_frame(3, p.HB))
    assert out == [p.BadFrame("too_long", body[:64]), p.Frame(3, "HB")]
    assert dec.junk_bytes == 0  # skipped bytes of an over-long frame are not junk


def test_a_line_of_exactly_max_line_bytes_in_the_stream_is_decoded():
    full = p.encode_frame(12345, p.SET, "1" * 16, "2" * 16, "3" * 13)
    assert len(full) == 64
    dec = p.FrameDecoder()
    assert dec.feed(full[:-1]) == []  # 63 bytes buffered: no verdict yet
    assert dec.feed(b"\n") == [p.Frame(12345, "SET", ("1" * 16, "2" * 16, "3" * 13))]


def test_bytes_outside_a_frame_are_counted_as_junk_and_cr_is_not():
    dec = p.FrameDecoder()
    frame = p.encode_frame(4, p.STA)
    out = dec.feed(b"abc\r\r\n" + frame + b"xy" + b"\n\n")
    assert out == [p.Frame(4, "STA")]
    assert dec.junk_bytes == 5  # a, b, c after nothing; x, y after the frame's newline
    out = dec.feed(b"\n")  # a newline outside a frame says nothing
    assert out == [] and dec.junk_bytes == 5


def test_the_decoder_hands_decode_line_the_frame_without_cr_and_newline():
    frame = p.encode_frame(8, p.SET, 3.0)
    split = frame[:5] + b"\r" + frame[5:-1] + b"\r\r\n"
    dec = p.FrameDecoder()
    got = []
    for i in range(len(split)):
        got += dec.feed(split[i : i + 1])
    assert got == [p.Frame(8, "SET", ("3.00",))]


# --- the status payload and the setpoint argument ----------------------------------------


def test_status_args_encode_the_documented_fields():
    assert p.status_args(p.MillStatus(20.0, 19.87, True, None)) == ("20.00", "19.87", "1", "OK")
    assert p.status_args(p.MillStatus(1.5, 0.0, False, "WDOG")) == ("1.50", "0.00", "0", "WDOG")


@pytest.mark.parametrize(
    ("args", "status"),
    [
        (("20.00", "19.87", "1", "OK"), p.MillStatus(20.0, 19.87, True, None)),
        (("0", "0", "0", "WDOG"), p.MillStatus(0.0, 0.0, False, "WDOG")),
        (("99999.99", "0.00", "0", "DRIVE"), p.MillStatus(99999.99, 0.0, False, "DRIVE")),
    ],
)
def test_parse_status_reads_the_documented_fields(args, status):
    assert p.parse_status(args) == status


@pytest.mark.parametrize(
    "args",
    [
        ("1.00", "1.00", "1"),
        ("1.00", "1.00", "1", "OK", "x"),
        ("1.00", "1.00", "2", "OK"),
        ("1.00", "1.00", "yes", "OK"),
        ("abc", "1.00", "1", "OK"),
        ("1.00", "abc", "1", "OK"),
        ("100000", "1.00", "1", "OK"),
        ("1.00", "-0.01", "1", "OK"),
    ],
)
def test_parse_status_refuses_a_malformed_status_and_quotes_it(args):
    with pytest.raises(p.ControlError, match=re.escape(f"malformed mill status {','.join(args)!r}")):
        p.parse_status(args)


def test_millstatus_as_dict_names_every_field():
    assert p.MillStatus(2.0, 1.0, True, "WDOG").as_dict() == {
        "setpoint_rpm": 2.0, "actual_rpm": 1.0, "running": True, "fault": "WDOG"}


@pytest.mark.parametrize(
    ("text", "rpm"),
    [("12", 12.0), ("+5", 5.0), ("0", 0.0), ("12345", 12345.0), ("1.5", 1.5), ("1.234", 1.234),
     ("123456", None), ("1.2345", None), ("1.", None), (".5", None), ("-0", None), ("1e2", None),
     (" 1", None), ("1 ", None), ("++1", None)],
)
def test_parse_rpm_arg_takes_plain_numbers_with_up_to_three_decimals(text, rpm):
    assert p.parse_rpm_arg(text) == rpm


def test_frame_payload_is_what_a_resend_is_compared_on():
    assert p.Frame(3, "SET", ("5.00",)).payload == "SET,5.00"
    assert p.Frame(3, "ACK", ("1", "2")).payload == "ACK,1,2"
    assert p.Frame(3, "STA").payload == "STA"


@pytest.mark.parametrize(("seq", "after"), [(0, 1), (1, 2), (65534, 65535), (65535, 1)])
def test_next_seq_walks_1_to_65535_and_never_returns_0(seq, after):
    assert p.next_seq(seq) == after
