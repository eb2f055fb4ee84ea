"""Rotary stage over the Zaber ASCII protocol (hw.interfaces.RotaryStage).

Protocol document: docs/protocols/zaber.md (sources and uncertainty of every byte below).

Requests are ``/<device> <axis> <command>\\n``; replies are ``@<dd> <a> <OK|RJ> <IDLE|BUSY> <flag>
<data>\\r\\n`` (``flag`` is ``--`` or the highest-priority warning: ``F*`` faults, ``W*`` warnings,
``N*`` notices). Used here: ``move abs <microsteps>``, ``move rel <microsteps>``, ``get pos``,
``get maxspeed``, the empty command (status poll) and, only with ``write_settings=True`` and an
explicit ``settings`` dict, ``set <setting> <value>``.

Options from the bench file (``options = { message_ids = true, checksums = true }``): with
``message_ids`` each attempt carries a message id (0…99, cycling) after the axis and a reply
whose id differs (a late reply to an earlier attempt) is skipped: the reply to this attempt may
still follow within the timeout; with ``checksums`` each
command ends with ``:XX`` (the 8-bit two's complement of the byte sum after ``/``) and a reply's
checksum is verified (a corrupted reply is retried). Unsolicited alerts (``!``, with
``comm.alert`` on) and info lines (``#``) before the reply are skipped, not taken as garbled.

Safety, all before any byte is sent: a target outside the soft limits raises ``SoftLimitError``
(the contract of ``hw.interfaces.RotaryStage``, shared with the twin's stage); the stage's
``maxspeed`` is read once and compared with the bench file's speed limit, and moves are refused if
it is faster (this driver never raises it). ``move_to`` never sleeps directly: the waits between
status polls go through the injectable ``sleep``; durations are measured with the injectable
``clock``. With an ``encoder`` (an AngleEncoder), ``move_to`` then corrects in closed loop until head 1
reads within ``tolerance_deg`` of the target ("the bench stops at commanded encoder readings").
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, cast

from benchtwin.hw.drivers.base import Command, InstrumentError, SerialInstrument, parse_float, parse_raw
from benchtwin.hw.interfaces import SoftLimitError, StageMove, StagePosition

__all__ = ["ZaberRotaryStage", "ZaberSettings", "ZaberReply", "format_zaber_reply", "parse_zaber_reply", "zaber_checksum"]

_REPLY = (rb"@(?P<dev>\d{2}) (?P<axis>\d+)(?: (?P<id>\d{1,2}|--))? (?P<reply>OK|RJ) (?P<state>IDLE|BUSY)"
          rb" (?P<flag>--|[FWN][A-Z]) (?P<data>[ -~]*?)(?::(?P<cs>[0-9A-Fa-f]{2}))?\r?\n")
MAX_SKIPPED_LINES = 8   # alerts/info lines (and stale replies) skipped before a reply
_STALE = re.compile(rb"@\d{2} \d+ (\d{1,2}) ")   # a reply's message id


def zaber_checksum(body: bytes) -> bytes:
    """Two hex digits that make the byte sum of ``body`` plus the checksum 0 mod 256 (zaber.md)."""
    return f"{(-sum(body)) & 0xFF:02X}".encode("ascii")


def parse_reply(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    dev, axis = int(m.group("dev")), int(m.group("axis"))
    want_dev, want_axis = getattr(inst, "device", dev), getattr(inst, "axis", axis)
    if (dev, axis) != (want_dev, want_axis) and axis != 0:
        raise ValueError(f"reply from device {dev} axis {axis}, expected {want_dev} {want_axis}")
    if m.group("cs") is not None:
        body = m.group(0)[1:m.start("cs") - m.start(0) - 1]
        if zaber_checksum(body) != m.group("cs").upper():
            raise ValueError(f"reply checksum {m.group('cs').decode()} does not match {zaber_checksum(body).decode()}")
    elif getattr(inst, "checksums", False):
        raise ValueError("reply without checksum (checksums are on)")
    want_id = getattr(inst, "_msg_id", None)
    if want_id is not None and m.group("id") is not None and int(m.group("id")) != want_id:
        raise ValueError(f"reply has message id {m.group('id').decode()}, expected {want_id:02d}")
    reply, flag, data = m.group("reply").decode(), m.group("flag").decode(), m.group("data").decode("ascii").strip()
    if reply == "RJ":
        raise InstrumentError(inst.name, cmd.name, f"stage rejected the command ({data})", m.group(0))
    if flag.startswith("F"):
        raise InstrumentError(inst.name, cmd.name, f"stage reports fault {flag}", m.group(0))
    return {"reply": reply, "busy": m.group("state") == b"BUSY", "flag": flag, "data": data}


parse_zaber_reply = parse_reply


@dataclass(frozen=True)
class ZaberReply:
    """The fields of one reply line (zaber.md): the data, the device and axis numbers, ``OK`` or
    ``RJ``, busy (``BUSY``) or idle, the warning flag (``--``: none) and the message id (None: the
    reply carries none)."""

    data: str | int = 0
    device: int = 1
    axis: int = 1
    reply: str = "OK"
    busy: bool = False
    flag: str = "--"
    msg_id: int | None = None


def format_zaber_reply(r: ZaberReply = ZaberReply(), *, checksum: bool = False) -> bytes:
    """The reply line ``r`` as the controller sends it, with its checksum when ``checksum`` (tests)."""
    mid = f" {r.msg_id:02d}" if r.msg_id is not None else ""
    body = f"{r.device:02d} {r.axis}{mid} {r.reply} {'BUSY' if r.busy else 'IDLE'} {r.flag} {r.data}".encode("ascii")
    if checksum:
        body += b":" + zaber_checksum(body)
    return b"@" + body + b"\r\n"


def _cmd(name: str, template: bytes) -> Command:
    return Command(name, template, _REPLY, "reply", b"\n")


@dataclass(frozen=True)
class ZaberSettings:
    """A Zaber stage's settings, from the bench file: microsteps per degree, soft limits (low, high
    in deg) and the bench's speed limit (deg/s), all required; device and axis numbers; the
    closed-loop tolerance (deg) and corrections at most; the status polls' interval and the move's
    timeout (s); Zaber's native speed unit (data per microstep/s); the stage settings written at the
    first move (only with ``write_settings`` and an explicit ``settings`` dict); message ids and
    checksums (zaber.md)."""

    microsteps_per_deg: float
    soft_limits_deg: tuple[float, float]
    max_speed_deg_s: float
    device: int = 1
    axis: int = 1
    tolerance_deg: float = 0.001
    max_corrections: int = 5
    poll_interval_s: float = 0.05
    move_timeout_s: float = 120.0
    speed_data_per_microstep_s: float = 1.6384
    write_settings: bool = False
    settings: Mapping[str, Any] | None = None
    message_ids: bool = False
    checksums: bool = False


_ZABER_FIELDS = tuple(f.name for f in fields(ZaberSettings))


class ZaberRotaryStage(SerialInstrument):
    """Zaber rotary stage. Constructor arguments beyond the common ones (all from the bench file):

    ``microsteps_per_deg`` (required), ``soft_limits_deg`` = (low, high) (required),
    ``max_speed_deg_s`` (required: the speed limit), ``device`` (1), ``axis`` (1) (``ZaberSettings``), ``encoder``
    (an AngleEncoder for closed-loop correction, or None), ``tolerance_deg`` (0.001),
    ``max_corrections`` (5), ``poll_interval_s`` (0.05), ``move_timeout_s`` (120),
    ``speed_data_per_microstep_s`` (1.6384: Zaber's native speed unit), ``write_settings`` (False)
    and ``settings`` ({}): settings are written (``set <k> <v>``) only when both are given, at the
    first move, and a ``maxspeed`` above the speed limit is refused.
    """

    KIND = "stage"
    MODEL = "Zaber rotary stage (ASCII protocol)"
    UNITS = {"angle_deg": "deg", "stage_deg": "deg", "target_deg": "deg", "error_deg": "deg", "duration_s": "s"}
    SERIAL_SETTINGS = {"baudrate": 115200, "bytesize": 8, "parity": "N", "stopbits": 1, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/zaber.md"
    DEFAULT_COMMANDS = {
        "move_abs": _cmd("move_abs", b"/{device} {axis} move abs {microsteps}\n"),
        "move_rel": _cmd("move_rel", b"/{device} {axis} move rel {microsteps}\n"),
        "get_pos": _cmd("get_pos", b"/{device} {axis} get pos\n"),
        "get_maxspeed": _cmd("get_maxspeed", b"/{device} {axis} get maxspeed\n"),
        "poll": _cmd("poll", b"/{device} {axis}\n"),
        "set": _cmd("set", b"/{device} {axis} set {setting} {value}\n"),
    }
    PARSERS = {"reply": parse_reply, "raw": parse_raw}

    def __init__(self, name: str, transport, stage: ZaberSettings | None = None, *, encoder: Any = None,
                 **kw: Any) -> None:
        """``stage`` (a ``ZaberSettings``), or its fields as keywords beside the common ones
        (``SerialInstrument``'s ``LinkSettings``); ``encoder``: an AngleEncoder for closed-loop
        correction, or None."""
        if stage is None:
            stage = ZaberSettings(**{k: kw.pop(k) for k in _ZABER_FIELDS if k in kw})
        super().__init__(name, transport, **kw)
        self.stage_settings = stage
        microsteps_per_deg, soft_limits_deg, max_speed_deg_s = (stage.microsteps_per_deg, stage.soft_limits_deg,
                                                                stage.max_speed_deg_s)
        settings, write_settings = stage.settings, stage.write_settings
        self.message_ids, self.checksums = bool(stage.message_ids), bool(stage.checksums)
        self._next_id = 0
        self._msg_id: int | None = None
        lo, hi = (float(v) for v in soft_limits_deg)
        if not lo < hi:
            raise ValueError(f"{name}: soft_limits_deg must be (low, high) with low < high, got {soft_limits_deg}")
        if not microsteps_per_deg or microsteps_per_deg <= 0:
            raise ValueError(f"{name}: microsteps_per_deg must be > 0, got {microsteps_per_deg}")
        if not max_speed_deg_s or max_speed_deg_s <= 0:
            raise ValueError(f"{name}: max_speed_deg_s must be > 0, got {max_speed_deg_s}")
        if settings and not write_settings:
            raise ValueError(f"{name}: settings given but write_settings is False; nothing is written to the "
                             f"stage unless write_settings=True")
        if write_settings and not settings:
            raise ValueError(f"{name}: write_settings=True needs an explicit settings dict")
        self.soft_limits_deg = (lo, hi)
        self.microsteps_per_deg = float(microsteps_per_deg)
        self.max_speed_deg_s = float(max_speed_deg_s)
        self.device, self.axis = int(stage.device), int(stage.axis)
        self.encoder = encoder
        self.tolerance_deg = float(stage.tolerance_deg)
        self.max_corrections = int(stage.max_corrections)
        self.poll_interval_s = float(stage.poll_interval_s)
        self.move_timeout_s = float(stage.move_timeout_s)
        self.speed_data_per_microstep_s = float(stage.speed_data_per_microstep_s)
        self.write_settings = bool(write_settings)
        self.settings = dict(settings or {})
        self._checked = False
        if "maxspeed" in self.settings:
            self._check_speed(float(self.settings["maxspeed"]), "settings['maxspeed']")

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "soft_limits_deg": list(self.soft_limits_deg),
                "max_speed_deg_s": self.max_speed_deg_s, "microsteps_per_deg": self.microsteps_per_deg,
                "device": self.device, "axis": self.axis, "tolerance_deg": self.tolerance_deg,
                "closed_loop": self.encoder is not None, "write_settings": self.write_settings,
                "message_ids": self.message_ids, "checksums": self.checksums}

    # --- framing (message ids, checksums, alerts) ------------------------------------------------
    def frame_request(self, cmd: Command, request: bytes) -> bytes:
        body = request.rstrip(b"\r\n")
        end = request[len(body):]
        if self.message_ids:
            self._msg_id = self._next_id
            self._next_id = (self._next_id + 1) % 100
            words = body.split(b" ")
            # "/<device> <axis> <id> <command>": the id goes after the axis (zaber.md)
            body = b" ".join(words[:2] + [f"{self._msg_id:02d}".encode("ascii")] + words[2:])
        if self.checksums:
            body += b":" + zaber_checksum(body[1:])
        return body + end

    def _read_reply(self, cmd: Command) -> bytes:
        """The ``@`` reply line; alerts (``!``) and info lines (``#``) before it are skipped, and so,
        with message ids, is a complete reply carrying another id (a late reply to an earlier
        attempt: the reply to this one may still follow within the timeout)."""
        line = b""
        for _ in range(MAX_SKIPPED_LINES + 1):
            line = self.transport.read_until(cmd.terminator)
            if not line.endswith(cmd.terminator):
                return line
            if line[:1] in (b"!", b"#"):
                continue
            if self.message_ids and self._msg_id is not None and line[:1] == b"@":
                m = _STALE.match(line)
                if m is not None and m.group(1) != f"{self._msg_id:02d}".encode("ascii"):
                    continue
            return line
        return line

    # --- helpers -----------------------------------------------------------------------------------
    def _q(self, command: str, **fields: Any) -> dict[str, Any]:
        return self.query(command, device=self.device, axis=self.axis, **fields)

    def _speed_deg_s(self, data: float) -> float:
        return data / self.speed_data_per_microstep_s / self.microsteps_per_deg

    def _check_speed(self, data: float, what: str) -> None:
        speed = self._speed_deg_s(data)
        if speed > self.max_speed_deg_s * (1 + 1e-9):
            raise InstrumentError(self.name, "maxspeed", f"{what} = {data:g} means {speed:.6g} deg/s, above the "
                                  f"bench's speed limit {self.max_speed_deg_s:g} deg/s; refusing to move "
                                  f"(lower maxspeed on the stage)", b"")

    def _check_limits(self, target_deg: float) -> None:
        lo, hi = self.soft_limits_deg
        if not (math.isfinite(target_deg) and lo <= target_deg <= hi):
            raise SoftLimitError(self.name, target_deg, (lo, hi))

    def _prepare(self) -> None:
        if self._checked:
            return
        if self.write_settings:
            for key, value in self.settings.items():
                self._q("set", setting=key, value=value)
        r = self._q("get_maxspeed")
        self._check_speed(parse_float(r["data"].split()[0], "maxspeed"), "stage maxspeed")
        self._checked = True

    def _wait_idle(self, t0: float, first: dict[str, Any]) -> None:
        r = first
        while r["busy"]:
            if self.clock() - t0 > self.move_timeout_s:
                raise InstrumentError(self.name, "poll", f"still BUSY after {self.move_timeout_s} s", b"")
            self.sleep(self.poll_interval_s)
            r = self._q("poll")

    def _microsteps(self, deg: float) -> int:
        return int(round(deg * self.microsteps_per_deg))

    def _stage_deg(self) -> float:
        return parse_float(self._q("get_pos")["data"].split()[0], "pos") / self.microsteps_per_deg

    # --- RotaryStage ------------------------------------------------------------------------------
    def position(self) -> StagePosition:
        """``{"angle_deg", "t_s", "status", "stage_deg"}``: head 1 of the encoder when one is given,
        else the stage's own position."""
        stage = self._stage_deg()
        if self.encoder is not None:
            enc = self.encoder.read()
            return cast(StagePosition, self.reading(angle_deg=float(enc["angle_deg"][0]), stage_deg=stage,
                                                    status=enc["status"]))
        return cast(StagePosition, self.reading(angle_deg=stage, stage_deg=stage))

    def move_to(self, target_deg: float) -> StageMove:
        target_deg = float(target_deg)
        self._check_limits(target_deg)
        self._prepare()
        t0 = self.clock()
        r = self._q("move_abs", microsteps=self._microsteps(target_deg))
        self._wait_idle(t0, r)
        status = "ok"
        corrections = 0
        error_deg = None
        if self.encoder is not None:
            status = "not_settled"
            for corrections in range(self.max_corrections + 1):
                enc = self.encoder.read()
                if enc.get("status", "ok") != "ok":
                    status = f"encoder_{enc['status']}"
                    break
                error_deg = (target_deg - float(enc["angle_deg"][0]) + 180.0) % 360.0 - 180.0
                if abs(error_deg) <= self.tolerance_deg:
                    status = "ok"
                    break
                if corrections == self.max_corrections:
                    break
                step = self._microsteps(error_deg)
                if step == 0:
                    break
                stage_now = self._stage_deg()
                self._check_limits(stage_now + step / self.microsteps_per_deg)
                r = self._q("move_rel", microsteps=step)
                self._wait_idle(t0, r)
        out = self.reading(target_deg=target_deg, status=status, corrections=corrections)
        out["duration_s"] = float(out["t_s"] - t0)
        if error_deg is not None:
            out["error_deg"] = error_deg
        return cast(StageMove, out)
