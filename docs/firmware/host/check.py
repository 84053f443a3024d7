"""Check the reference sketch against control/device.py (needs g++; run from the repo root).

    .venv/bin/python docs/firmware/host/check.py

Builds mill_board.ino for the host with a tiny Arduino shim (Serial = stdin/stdout),
feeds it good, resent, refused and garbled frames, and compares its replies byte for
byte with the Python firmware model that the emulator runs.
"""

import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))

from control import protocol as p  # noqa: E402
from control.device import MillDevice  # noqa: E402

FRAMES = [
    p.encode_frame(1, p.SET, 12.5),
    p.encode_frame(1, p.SET, 12.5),  # resend: same answer, applied once
    p.encode_frame(2, p.RUN),
    p.encode_frame(3, "FOO"),
    p.encode_frame(4, p.SET, 99.0),
    p.encode_frame(5, p.SET, "abc"),
    b"$6,RUN*0000\n",
    p.encode_frame(7, p.STP, "x"),
    b"$8,SET," + b"9" * 100 + b"\n",
    b"\x00\xff garbage \n",
    p.encode_frame(9, p.STP),
    p.encode_frame(9, p.STA),  # read-only: a fresh status, the STP stays cached
    p.encode_frame(9, p.HB),
    p.encode_frame(9, p.STP),  # resend of the STP: the cached ACK
    p.encode_frame(10, p.SET, "+3.125"),
]

with tempfile.TemporaryDirectory() as tmp:
    exe = Path(tmp) / "fw"
    subprocess.run(["g++", "-I", str(HERE), "-o", str(exe), str(HERE / "main.cpp")], check=True)
    out = subprocess.run([str(exe)], input=b"".join(FRAMES), capture_output=True, timeout=10).stdout
dev = MillDevice()
expected = b"".join(dev.receive(f, 0.0) for f in FRAMES)
print(out.decode(), end="")
print("firmware matches control/device.py" if out == expected else "MISMATCH, expected:\n" + expected.decode())
sys.exit(0 if out == expected else 1)
