"""Zaber rotary stage over the ASCII protocol, emulated (docs/protocols/zaber.md).

Requests ``/<device> <axis> <command> [args]`` LF; replies ``@<dd> <a> <OK|RJ> <IDLE|BUSY> <flag>
<data>`` CR LF with flag ``--``. Emulated commands: ``move abs <microsteps>``, ``move rel
<microsteps>`` (the move is done on the twin at once; the reply says BUSY and the next
``busy_polls`` status polls too, then IDLE, so a driver's wait loop is exercised), the empty
command (status poll), ``get pos``, ``get maxspeed`` (the twin's stage speed in Zaber's unit:
microsteps/s × 1.6384), ``set <setting> <value>`` (stored; ``set maxspeed`` changes nothing on the
twin), ``stop`` and ``home`` (a move to 0). A request for another device is ignored (no reply);
a device 0 request is answered by this device. Unknown commands: ``RJ ... BADCOMMAND``; bad
numbers: ``RJ ... BADDATA``. Not emulated (as in the driver): message ids, checksums, alerts.
"""

from __future__ import annotations

from typing import Any

from ._base import ProtocolEmulator

__all__ = ["ZaberEmulator"]

SPEED_UNIT = 1.6384  # Zaber data units per (microstep/s)


class ZaberEmulator(ProtocolEmulator):
    PROTOCOL = "zaber"
    PROTOCOL_DOC = "docs/protocols/zaber.md"
    DRIVER = "zaber"
    SERIAL = {"baudrate": 115200, "bytesize": 8, "parity": "N", "stopbits": 1}

    def __init__(self, name: str, source: Any, microsteps_per_deg: float = 1000.0, device: int = 1,
                 axis: int = 1, busy_polls: int = 1, speed_deg_s: float | None = None):
        super().__init__(name, source)
        self.microsteps_per_deg = float(microsteps_per_deg)
        self.device, self.axis = int(device), int(axis)
        self.busy_polls = int(busy_polls)
        self._busy_left = 0
        self.position_deg = float(getattr(source, "position_deg", 0.0) or 0.0)
        self.speed_deg_s = float(speed_deg_s if speed_deg_s is not None else getattr(source, "speed_deg_s", 20.0))
        self.settings: dict[str, str] = {}

    def _reply(self, data: Any = 0, ok: bool = True, axis: int | None = None) -> bytes:
        state = "BUSY" if self._busy_left > 0 else "IDLE"
        a = self.axis if axis is None else axis
        return f"@{self.device:02d} {a} {'OK' if ok else 'RJ'} {state} -- {data}\r\n".encode("ascii")

    def _move(self, target_deg: float) -> None:
        self.position_deg = float(self.source.move(target_deg))
        self._busy_left = self.busy_polls + 1  # the move's own reply, then busy_polls polls

    def handle(self, request: bytes) -> bytes | None:
        text = request.decode("ascii", "replace").strip()
        if not text.startswith("/"):
            return None
        parts = text[1:].split()
        try:
            dev = int(parts[0]) if parts else 0
            axis = int(parts[1]) if len(parts) > 1 else 0
        except ValueError:
            return None
        if dev not in (0, self.device) or axis not in (0, self.axis):
            return None
        args = parts[2:]
        try:
            reply = self._command(args, axis)
        except ValueError:
            reply = self._reply("BADDATA", ok=False, axis=axis)
        if self._busy_left > 0:
            self._busy_left -= 1
        return reply

    def _command(self, args: list[str], axis: int) -> bytes:
        msd = self.microsteps_per_deg
        if not args:
            return self._reply(0, axis=axis)
        if args[0] == "move" and len(args) == 3 and args[1] in ("abs", "rel"):
            n = int(args[2])
            target = n / msd if args[1] == "abs" else self.position_deg + n / msd
            self._move(target)
            return self._reply(0, axis=axis)
        if args[0] == "home" and len(args) == 1:
            self._move(0.0)
            return self._reply(0, axis=axis)
        if args[0] == "stop" and len(args) == 1:
            self._busy_left = 0
            return self._reply(0, axis=axis)
        if args[0] == "get" and len(args) == 2:
            if args[1] == "pos":
                return self._reply(int(round(self.position_deg * msd)), axis=axis)
            if args[1] == "maxspeed":
                if "maxspeed" in self.settings:
                    return self._reply(self.settings["maxspeed"], axis=axis)
                return self._reply(int(round(self.speed_deg_s * msd * SPEED_UNIT)), axis=axis)
            if args[1] in self.settings:
                return self._reply(self.settings[args[1]], axis=axis)
            return self._reply("BADDATA", ok=False, axis=axis)
        if args[0] == "set" and len(args) == 3:
            float(args[2])
            self.settings[args[1]] = args[2]
            return self._reply(0, axis=axis)
        return self._reply("BADCOMMAND", ok=False, axis=axis)
