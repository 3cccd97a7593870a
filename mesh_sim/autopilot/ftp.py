"""MAVLink FTP (https://mavlink.io/en/services/ftp.html): this simulator has no file system, so every request
is answered with a NAK ``FileNotFound``.

That is what PX4 answers for a path it does not have, and it lets a client fall back at once instead of
timing out: MAVProxy, for one, first asks for ``@PARAM/param.pck`` over FTP and only then uses the
parameter protocol. The payload (``FILE_TRANSFER_PROTOCOL.payload``, 251 bytes) starts with the header
``seq_number u16, session u8, opcode u8, size u8, req_opcode u8, burst_complete u8, padding u8, offset u32``
followed by ``data``; a NAK has ``opcode`` 129, the request's opcode in ``req_opcode``, ``seq_number`` one
more than the request's, and the error code in ``data[0]``.
"""

from __future__ import annotations

import struct

HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_LEN = 251
OPCODE_ACK, OPCODE_NAK = 128, 129
ERROR_FILE_NOT_FOUND = 10


def nak(request_payload) -> list[int] | None:
    """The payload of the NAK answering ``request_payload``; ``None`` for a payload too short to be a request."""
    payload = bytes(request_payload)
    if len(payload) < HEADER.size:
        return None
    seq, session, opcode, _, _, _, _, _ = HEADER.unpack_from(payload)
    if opcode in (OPCODE_ACK, OPCODE_NAK):  # an answer, not a request
        return None
    reply = HEADER.pack((seq + 1) & 0xFFFF, session, OPCODE_NAK, 1, opcode, 0, 0, 0) + bytes([ERROR_FILE_NOT_FOUND])
    return list(reply.ljust(PAYLOAD_LEN, b"\0"))
