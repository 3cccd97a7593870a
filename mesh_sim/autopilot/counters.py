"""What the simulator received, sent and refused, counted by reason (DESIGN §5: input is counted, never fatal)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field


@dataclass
class Counters:
    datagrams: int = 0  # UDP datagrams read, both links
    kernel_drops: int = 0  # datagrams the kernel dropped before they were read (receive buffer full)
    bytes: int = 0
    messages: int = 0  # MAVLink messages decoded
    sent: int = 0  # datagrams sent
    send_errors: int = 0  # sendto failures (e.g. ICMP port unreachable from a client that went away)
    received: Counter = field(default_factory=Counter)  # message type -> count
    rejected: Counter = field(default_factory=Counter)  # reason -> count

    def reject(self, reason: str, count: int = 1) -> None:
        self.rejected[reason] += count

    def as_dict(self) -> dict:
        return {
            "datagrams": self.datagrams,
            "kernel_drops": self.kernel_drops,
            "bytes": self.bytes,
            "messages": self.messages,
            "sent": self.sent,
            "send_errors": self.send_errors,
            "received": dict(sorted(self.received.items())),
            "rejected": dict(sorted(self.rejected.items())),
        }
