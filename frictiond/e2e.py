"""End-to-end protection of the output frames (can-contract.md, AUTOSAR E2E Profile 1 style).

`Crc` (byte 0) is CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, final XOR 0xFF) over the 16-bit Data ID
(low byte first; Data ID = the frame ID) followed by payload bytes 1..7. `Counter` counts each
message's frames modulo 16.
"""
from __future__ import annotations

from dataclasses import dataclass, field


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc8_sae_j1850(data: bytes | bytearray, crc: int = 0xFF) -> int:
    """CRC-8/SAE-J1850: check value of b"123456789" is 0x4B."""
    for byte in data:
        crc = _TABLE[crc ^ byte]
    return crc ^ 0xFF


def e2e_crc(data_id: int, payload: bytes | bytearray) -> int:
    """The `Crc` byte for a frame: over Data ID (low, high) then payload bytes 1..7."""
    # The table steps of crc8_sae_j1850 over the two ID bytes, without building a joined copy.
    crc = _TABLE[0xFF ^ (data_id & 0xFF)]
    crc = _TABLE[crc ^ ((data_id >> 8) & 0xFF)]
    return crc8_sae_j1850(payload[1:8], crc)


def protect(data_id: int, payload: bytearray, counter: int, counter_bit: int = 8) -> bytearray:
    """Write the 4-bit counter at `counter_bit` (low nibble of byte 1 by default) and the CRC into byte 0."""
    byte, shift = divmod(counter_bit, 8)
    payload[byte] = (payload[byte] & ~(0x0F << shift) & 0xFF) | ((counter & 0x0F) << shift)
    payload[0] = e2e_crc(data_id, payload)
    return payload


@dataclass
class E2EChecker:
    """Receiver side: CRC verdicts and counter continuity per Data ID."""

    crc_failures: int = 0
    counter_jumps: int = 0
    frames_lost: int = 0
    repeated: int = 0
    frames_ok: int = 0
    _last_counter: dict[int, int] = field(default_factory=dict)

    def check(self, data_id: int, payload: bytes, counter_bit: int = 8) -> str:
        """'ok', 'crc' (corrupt), 'repeated' or 'jump' (frames lost in between)."""
        if len(payload) < 2 or e2e_crc(data_id, payload) != payload[0]:
            self.crc_failures += 1
            return "crc"
        byte, shift = divmod(counter_bit, 8)
        counter = (payload[byte] >> shift) & 0x0F
        last = self._last_counter.get(data_id)
        self._last_counter[data_id] = counter
        if last is None:
            self.frames_ok += 1
            return "ok"
        delta = (counter - last) % 16
        if delta == 1:
            self.frames_ok += 1
            return "ok"
        if delta == 0:
            self.repeated += 1
            return "repeated"
        self.counter_jumps += 1
        self.frames_lost += delta - 1
        return "jump"

    def reset(self) -> None:
        self.crc_failures = self.counter_jumps = self.frames_lost = self.repeated = self.frames_ok = 0
        self._last_counter.clear()
