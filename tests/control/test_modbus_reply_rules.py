"""The reply checker (control/modbus/reply.py) on hand-made RTU frames, rule by rule: a read
whose frame is whole but whose byte count disagrees, and what the error shows of bytes that are
no answer at all (pure; the CRC from pymodbus, an implementation independent of ours)."""

from __future__ import annotations

import pytest

from control.modbus.reply import READ, BadReply, Request, check_reply


def _frame(*parts: int) -> bytes:
    from pymodbus.framer import FramerRTU

    body = bytes(parts)
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


READ2 = Request(1, READ, 0x2100, count=2)


def test_a_whole_frame_whose_byte_count_is_not_twice_the_quantity_is_refused_naming_both() -> None:
    """9 bytes, a valid CRC, the right unit and function: only the byte count (5, not 4) is wrong."""
    with pytest.raises(BadReply) as e:
        check_reply(READ2, _frame(1, 3, 5, 0, 7, 0x12, 0x34))
    assert str(e.value) == "byte count 5 for 2 registers"


@pytest.mark.parametrize(("n", "shown"), [(16, "00 01 02 03 04 05 06 07 08 09 0a 0b 0c 0d 0e 0f"),
                                          (17, "00 01 02 03 04 05 06 07 08 09 0a 0b 0c 0d 0e 0f ...")])
def test_junk_is_shown_by_its_first_16_bytes_and_an_ellipsis_when_there_are_more(n: int, shown: str) -> None:
    with pytest.raises(BadReply) as e:
        check_reply(READ2, bytes(range(n)))
    assert str(e.value) == f"{n} bytes ({shown}) are not the 9-byte answer to function 0x03 (nor an exception)"
