"""Zaber rotary stage over the Zaber ASCII protocol, emulated (docs/protocols/zaber.md).

Messages, as the Zaber ASCII protocol manual gives them:

- command ``/[device] [axis] [message id] <command> [data][:checksum]`` LF (CR LF accepted);
  device 0 or none: every device; axis 0 or none: the device itself;
- reply ``@<dd> <a> [id] <OK|RJ> <IDLE|BUSY> <flag> <data>[:checksum]`` CR LF; the message id
  (0…99, or ``--``) is echoed when the command had one;
- info ``#<dd> <a> [id] <text>`` CR LF (extra lines of a reply: here ``warnings`` and ``help``);
- alert ``!<dd> <a> <IDLE|BUSY> <flag>`` CR LF, unsolicited, when a move ends and ``comm.alert`` is 1;
- checksum: the 8-bit two's complement of the byte sum of everything between the leading
  ``/``/``@`` and the ``:``, as two upper-case hex digits; a command with a wrong checksum is
  dropped (no reply); replies carry one when the command did or ``comm.checksum`` is 1;
- warning flag: ``--`` or the highest-priority current warning (``F*`` fault > ``W*`` warning >
  ``N*`` notice); ``warnings`` lists them all, ``warnings clear`` clears the clearable ones.

Commands: the empty command (status), ``move abs|rel|min|max [data]``, ``home``, ``stop``,
``estop``, ``get <setting>``, ``set <setting> <value>``, ``warnings [clear]``, ``help``, ``system
reset`` (restores the settings), ``tools echo``. Settings (device scope: ``deviceid``,
``system.serial``, ``version``, ``version.build``, ``system.axiscount``, ``comm.alert``,
``comm.checksum``, ``comm.address``, ``comm.rs232.baud``, ``comm.protocol``, ``system.access``;
axis scope: ``pos``, ``resolution``, ``limit.min``, ``limit.max``, ``limit.cycle.dist``,
``maxspeed``, ``accel``, ``peripheral.id``, ``encoder.pos``, ``motion.index.dist``…). ``get`` of an
axis setting at axis 0 answers every axis, as a device does; a device setting at an axis > 0 is
``RJ … BADAXIS``. Unknown commands ``RJ … BADCOMMAND``, bad numbers ``RJ … BADDATA``, a target
outside ``limit.min``…``limit.max`` ``RJ … BADDATA``, a bad message id ``RJ … BADMESSAGEID``.

The identity is meant as a Zaber rotary stage with integrated controller (``deviceid`` and firmware
``version`` below are our choices, not checked against Zaber's device database: docs/protocols/zaber.md
says so, and what a client cannot get without that database). The
move is done on the twin at once; the reply says BUSY and so do the next ``busy_polls`` status
polls, then IDLE, so a client's wait loop is exercised. The stage's native unit is the microstep:
``microsteps_per_deg`` (1000 on the emulated bench) is the conversion a client gets from
``get resolution`` together with the stage's full-step angle (docs/protocols/zaber.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from ._base import ProtocolEmulator

__all__ = ["ZaberEmulator", "zaber_checksum", "ROTARY_DEVICE_ID"]

SPEED_UNIT = 1.6384  # Zaber data units per (microstep/s)
# Our choice, meant as an integrated rotary stage; NOT verified against Zaber's device database
# (unreachable from here): docs/protocols/zaber.md, "identity". Option ``device_id`` overrides it.
ROTARY_DEVICE_ID = 50419
FIRMWARE = "7.38"
FIRMWARE_BUILD = "17690"

_WARN_PRIORITY = {"F": 0, "W": 1, "N": 2}
_CLEARABLE = {"WL", "WV", "WO", "WM", "WP", "NC", "NI", "ND", "NU", "NJ", "NB", "NT"}
_DEVICE_SETTINGS = ("deviceid", "system.serial", "version", "version.build", "system.axiscount", "comm.alert",
                    "comm.checksum", "comm.address", "comm.rs232.baud", "comm.protocol", "system.access",
                    "system.current", "system.voltage", "system.temperature")


def zaber_checksum(body: bytes) -> str:
    """Two hex digits that make the byte sum of ``body`` plus the checksum 0 mod 256."""
    return f"{(-sum(body)) & 0xFF:02X}"


@dataclass(frozen=True)
class ZaberDeviceSpec:
    """The emulated controller and stage: microsteps per degree, device and axis numbers, status
    polls answered BUSY after a move, speed (deg/s; None: the backend's, else 20), the device's
    identity (device id, serial number, firmware version), and the motor's full step (deg at the
    motor) and gear ratio (which with microsteps_per_deg give the resolution setting)."""

    microsteps_per_deg: float = 1000.0
    device: int = 1
    axis: int = 1
    busy_polls: int = 1
    speed_deg_s: float | None = None
    device_id: int = ROTARY_DEVICE_ID
    serial_number: int = 70001
    version: str = FIRMWARE
    step_deg: float = 1.8
    gear_ratio: float = 1.0


class ZaberEmulator(ProtocolEmulator):
    PROTOCOL = "zaber"
    PROTOCOL_DOC = "docs/protocols/zaber.md"
    DRIVER = "zaber"
    SERIAL = {"baudrate": 115200, "bytesize": 8, "parity": "N", "stopbits": 1}
    TCP_PORT = 55550   # Zaber's ASCII-over-TCP port on its Ethernet controllers (zaber.md)

    def __init__(self, name: str, source: Any, spec: ZaberDeviceSpec = ZaberDeviceSpec()):
        super().__init__(name, source)
        self.spec = spec
        self.microsteps_per_deg = float(spec.microsteps_per_deg)
        self.device, self.axis = int(spec.device), int(spec.axis)
        self.busy_polls = int(spec.busy_polls)
        self._busy_left = 0
        self._moving = False
        self.position_deg = float(getattr(source, "position_deg", 0.0) or 0.0)
        self.speed_deg_s = float(spec.speed_deg_s if spec.speed_deg_s is not None
                                 else getattr(source, "speed_deg_s", 20.0))
        self.device_id, self.serial_number, self.version = int(spec.device_id), int(spec.serial_number), str(spec.version)
        # microstep resolution: microsteps per full step of the motor (step_deg at the output shaft
        # with gear_ratio); the emulated stage's microsteps_per_deg fixes it
        self.microsteps_per_step = self.microsteps_per_deg * float(spec.step_deg) / float(spec.gear_ratio)
        self.warnings: set[str] = set()
        self.settings: dict[str, str] = {}
        self._defaults()

    # ------------------------------------------------------------------ settings
    def _defaults(self) -> None:
        msd = self.microsteps_per_deg
        self.device_settings = {
            "deviceid": str(self.device_id), "system.serial": str(self.serial_number), "version": self.version,
            "version.build": FIRMWARE_BUILD, "system.axiscount": "1", "comm.alert": "0", "comm.checksum": "0",
            "comm.address": str(self.device), "comm.rs232.baud": str(self.SERIAL["baudrate"]),
            "comm.protocol": "1", "system.access": "1", "system.current": "0.42", "system.voltage": "48.1",
            "system.temperature": "31.5"}
        self.axis_settings = {
            "resolution": f"{self.microsteps_per_step:.10g}", "limit.min": str(int(round(-360 * msd))),
            "limit.max": str(int(round(720 * msd))), "limit.cycle.dist": str(int(round(360 * msd))),
            "accel": "205", "peripheral.id": "0", "motion.index.dist": "0",
            "maxspeed": str(int(round(self.speed_deg_s * msd * SPEED_UNIT))),
            "knob.enable": "1", "driver.enabled": "1"}

    def _get(self, key: str) -> str | None:
        msd = self.microsteps_per_deg
        if key in ("pos", "encoder.pos"):
            return str(int(round(self.position_deg * msd)))
        if key in self.device_settings:
            return self.device_settings[key]
        return self.axis_settings.get(key)

    # ------------------------------------------------------------------ framing
    def on_connect(self) -> None:
        pass  # the controller keeps its state across host connections

    def _flag(self) -> str:
        if not self.warnings:
            return "--"
        return sorted(self.warnings, key=lambda w: (_WARN_PRIORITY.get(w[0], 3), w))[0]

    def _state(self) -> str:
        return "BUSY" if self._busy_left > 0 else "IDLE"

    def _line(self, kind: str, axis: int, msg_id: str | None, body: str, checksum: bool) -> bytes:
        head = f"{self.device:02d} {axis}" + (f" {msg_id}" if msg_id is not None else "")
        text = f"{head} {body}".encode("ascii")
        if checksum:
            text += b":" + zaber_checksum(text).encode("ascii")
        return kind.encode("ascii") + text + b"\r\n"

    def handle(self, request: bytes) -> bytes | None:
        text = request.decode("ascii", "replace").strip()
        at = text.find("/")
        if at < 0:
            return None                # not a command: line noise
        text = text[at + 1:]
        checksum = False
        if ":" in text:
            text, cs = text.rsplit(":", 1)
            if not re.fullmatch(r"[0-9A-Fa-f]{2}", cs) or zaber_checksum(text.encode("ascii")) != cs.upper():
                return None            # a corrupted command is dropped (zaber.md)
            checksum = True
        checksum = checksum or self.device_settings["comm.checksum"] == "1"
        parts = text.split()
        dev = axis = 0
        msg_id: str | None = None
        k = 0
        if k < len(parts) and parts[k].isdigit():
            dev, k = int(parts[k]), k + 1
            if k < len(parts) and parts[k].isdigit():
                axis, k = int(parts[k]), k + 1
                if k < len(parts) and (parts[k].isdigit() or parts[k] == "--"):
                    msg_id, k = parts[k], k + 1
        if dev not in (0, self.device):
            return None                # another device on the chain
        args = parts[k:]
        was_busy = self._busy_left > 0
        if msg_id is not None and msg_id != "--" and not 0 <= int(msg_id) <= 99:
            body = self._body("BADMESSAGEID", ok=False)
        elif axis not in (0, self.axis):
            body = self._body("BADAXIS", ok=False)
        else:
            try:
                body = self._command(args, axis)
            except ValueError:
                body = self._body("BADDATA", ok=False)
        info = b""
        if isinstance(body, tuple):
            body, lines = body
            info = b"".join(self._line("#", axis, msg_id, ln, checksum) for ln in lines)
        reply = self._line("@", axis, msg_id, body, checksum) + info
        if self._busy_left > 0:
            self._busy_left -= 1
        if was_busy and self._busy_left == 0 and self._moving:
            self._moving = False
            if self.device_settings["comm.alert"] == "1":
                reply += self._line("!", self.axis, None, f"IDLE {self._flag()}", checksum)
        return reply

    def _body(self, data: Any = 0, ok: bool = True) -> str:
        return f"{'OK' if ok else 'RJ'} {self._state()} {self._flag()} {data}"

    # ------------------------------------------------------------------ commands
    def _move(self, target_deg: float) -> None:
        msd = self.microsteps_per_deg
        lo, hi = int(self.axis_settings["limit.min"]), int(self.axis_settings["limit.max"])
        if not lo <= round(target_deg * msd) <= hi:
            raise ValueError("target outside limit.min..limit.max")
        self.position_deg = float(self.source.move(target_deg))
        self._busy_left = self.busy_polls + 1  # the move's own reply, then busy_polls polls
        self._moving = True

    def _command(self, args: list[str], axis: int) -> Any:
        msd = self.microsteps_per_deg
        if not args:
            return self._body(0)
        cmd = args[0]
        if cmd == "move" and len(args) >= 2:
            mode = args[1]
            if mode in ("abs", "rel") and len(args) == 3:
                n = int(args[2])
                self._move(n / msd if mode == "abs" else self.position_deg + n / msd)
                return self._body(0)
            if mode in ("min", "max") and len(args) == 2:
                self._move(int(self.axis_settings[f"limit.{mode}"]) / msd)
                return self._body(0)
            return self._body("BADCOMMAND", ok=False)
        if cmd == "home" and len(args) == 1:
            self._move(0.0)
            self.warnings.discard("WR")
            return self._body(0)
        if cmd in ("stop", "estop") and len(args) == 1:
            self._busy_left = 0
            self._moving = False
            return self._body(0)
        if cmd == "get" and len(args) == 2:
            key = args[1]
            value = self._get(key)
            if value is None:
                return self._body("BADCOMMAND", ok=False)
            if axis and key in self.device_settings:
                return self._body("BADAXIS", ok=False)
            return self._body(value)
        if cmd == "set" and len(args) == 3:
            key, value = args[1], args[2]
            float(value)
            if key in ("pos", "encoder.pos"):
                return self._body("BADCOMMAND", ok=False)   # not emulated: the twin owns the angle
            if key in ("deviceid", "version", "version.build", "system.serial", "system.axiscount",
                       "peripheral.id", "resolution"):
                return self._body("BADDATA", ok=False)      # read-only here (resolution: see zaber.md)
            if key in self.device_settings:
                if axis:
                    return self._body("BADAXIS", ok=False)
                self.device_settings[key] = value
            elif key in self.axis_settings:
                self.axis_settings[key] = value
            else:
                return self._body("BADCOMMAND", ok=False)
            self.settings[key] = value
            return self._body(0)
        if cmd == "warnings" and len(args) <= 2:
            if len(args) == 2 and args[1] != "clear":
                return self._body("BADCOMMAND", ok=False)
            flags = sorted(self.warnings, key=lambda w: (_WARN_PRIORITY.get(w[0], 3), w))
            body = self._body(" ".join([f"{len(flags):02d}", *flags]))
            if len(args) == 2:
                self.warnings -= _CLEARABLE
            return body
        if cmd == "system" and args[1:] == ["reset"]:
            self._defaults()
            self.warnings = set()
            return self._body(0)
        if cmd == "tools" and len(args) >= 2 and args[1] == "echo":
            return self._body(" ".join(args[2:]) or 0)
        if cmd == "help" and len(args) == 1:
            return self._body(0), ["benchtwin emulated Zaber ASCII device: see docs/protocols/zaber.md"]
        return self._body("BADCOMMAND", ok=False)
