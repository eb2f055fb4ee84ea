"""Bench files (TOML, docs/bench-file.md): which instrument on which port, the stage's limits, the
procedures to run and the dataset manifest's bench geometry.

    cfg = load_bench("bench.toml")            # BenchFileError names file, key and what was expected
    steps = build_procedure(cfg)              # procedure steps (hw.acquisition.procedures)
    inst = open_instruments(cfg, sleep=..., clock=...)   # {name: driver}; ports opened here
    manifest = dataset_manifest(cfg)

Drivers are built from ``benchtwin.hw.drivers`` through ``open_transport(port,
**Driver.serial_settings(**section.serial))``; instruments that name the same port share one
transport (``SharedPort``: the channels of a Millimar amplifier). Every driver gets a ``reconnect``
callable re-opening its port (unless ``reconnect = false``). This module never imports the twin.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchtwin.schema import Key, SchemaError, check_table, check_version, loads_toml, read_input_text
from benchtwin.units import ARCSEC, DEG, UnitError, parse_quantity

from . import procedures as P

__all__ = ["BenchFileError", "BenchConfig", "DRIVERS", "load_bench", "parse_bench", "build_procedure", "iter_procedure",
           "open_instruments", "dataset_manifest", "close_instruments"]

# driver name in the bench file -> (module, class)
DRIVERS: dict[str, tuple[str, str]] = {
    "elcomat": ("benchtwin.hw.drivers.elcomat", "Elcomat"),
    "triangle": ("benchtwin.hw.drivers.triangle", "TriAngle"),
    "tesa": ("benchtwin.hw.drivers.tesa", "TesaTT"),
    "millimar": ("benchtwin.hw.drivers.millimar", "MillimarC1202"),
    "heidenhain": ("benchtwin.hw.drivers.heidenhain", "HeidenhainND"),
    "zaber": ("benchtwin.hw.drivers.zaber", "ZaberRotaryStage"),
    # cameras: not serial; ``port`` is the folder (folder, watch_folder) or the VideoCapture source (opencv)
    "folder": ("benchtwin.hw.drivers.camera", "FolderCamera"),
    "watch_folder": ("benchtwin.hw.drivers.camera", "WatchFolderCamera"),
    "opencv": ("benchtwin.hw.drivers.camera", "OpenCVCamera"),
}
CAMERA_DRIVERS = ("folder", "watch_folder", "opencv")
SOURCES = ("hardware", "emulated")
PROCEDURES = P.PROCEDURE_TYPES

_TOP = {"bench", "geometry", "run", "instruments", "procedure", "ccd"}
_CCD = {"position": "angle", "tangential": None, "reference_px": None, "pixel_size": "length"}
_BENCH = {"name", "source", "description", "session"}
_GEOMETRY = {"optical_radius": "length", "L1": "length", "L2": "length", "grating_period": "length",
             "polygon_faces": None, "heads": "angle", "encoder_lines": None, "encoder_resolution": "angle",
             "polygon_certificate": "angle", "scale_edge_radius": "length",
             "autocollimator_resolution": "angle", "autocollimator_accuracy": "angle"}
_GEOMETRY_REQUIRED = ("optical_radius", "L1", "L2", "grating_period", "polygon_faces")
_INSTRUMENT = {"driver", "port", "serial", "options", "commands", "retries", "backoff", "reconnect",
               "soft_limits", "max_speed", "closed_loop_encoder", "heads"}
_SERIAL = {"baudrate", "bytesize", "parity", "stopbits", "timeout", "xonxoff", "rtscts"}
_PROC_KEYS = P.PROCEDURE_PARAMS  # the procedure language (hw/acquisition/procedures.py)


class BenchFileError(ValueError):
    """An invalid bench file; the message names the file, the key and what was expected."""


@dataclass
class BenchConfig:
    path: Path | None
    raw: dict[str, Any]
    name: str
    source: str
    geometry: dict[str, Any]          # manifest["bench"] (units in the key names)
    run: dict[str, Any]
    instruments: dict[str, dict[str, Any]]
    procedures: list[dict[str, Any]] = field(default_factory=list)
    text: str | None = None
    ccd: dict[str, Any] | None = None  # manifest["ccd"] (the [ccd] section), for a CCD sweep
    session: str | None = None         # [bench] session: the emulator session that wrote the file (None: hardware)


# --------------------------------------------------------------------------- loading

def load_bench(path: str | Path) -> BenchConfig:
    p = Path(path)
    if not p.exists():
        raise BenchFileError(f"{p}: no such bench file")
    try:  # bounded, regular, UTF-8, nesting-limited, finite numbers (benchtwin.schema; issue #13)
        text = read_input_text(p, what="bench file")
        raw = loads_toml(text, str(p))
    except SchemaError as exc:
        raise BenchFileError(str(exc)) from None
    cfg = parse_bench(raw, str(p))
    cfg.path, cfg.text = p, text
    return cfg


def _fail(where: str, key: str, expected: str, got: Any = None) -> BenchFileError:
    tail = "" if got is None else f", got {got!r}"
    return BenchFileError(f"{where}: key '{key}': expected {expected}{tail}")


def _table(node: Any, where: str, key: str, known: set[str] | None = None, required: bool = True) -> dict:
    if node is None:
        if required:
            raise BenchFileError(f"{where}: missing section [{key}]")
        return {}
    if not isinstance(node, Mapping):
        raise _fail(where, key, "a table", node)
    if known is not None:
        unknown = sorted(set(node) - known)
        if unknown:
            raise BenchFileError(f"{where}: [{key}]: unknown key(s) {unknown}; known: {sorted(known)}")
    return dict(node)


def _q(value: Any, dim: str, where: str, key: str) -> float:
    try:
        return parse_quantity(value, dim)
    except UnitError as exc:
        raise _fail(where, key, f"a quantity with a unit of dimension {dim} ({exc})", value) from None


def _int(value: Any, where: str, key: str, lo: int | None = None) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or (lo is not None and value < lo):
        raise _fail(where, key, "an integer" + (f" >= {lo}" if lo is not None else ""), value)
    return int(value)


def _fmt(x: float) -> float:
    return float(f"{x:.12g}")


def parse_bench(raw: Mapping[str, Any], where: str = "<bench>") -> BenchConfig:
    """Validate a parsed bench file (see docs/bench-file.md).

    The checks below name each key; a value of a type no check foresaw (found by the fuzz tests,
    tests/benchtwin/test_fuzz_readers.py) still ends as ``BenchFileError`` naming the section, never as a
    TypeError (issue #13)."""
    section = ["the top level"]
    try:
        return _parse_bench(raw, where, section)
    except BenchFileError:
        raise
    except (TypeError, KeyError, AttributeError, IndexError, ValueError, OverflowError) as exc:
        raise BenchFileError(f"{where}: {section[0]}: a value of the wrong type or shape ({type(exc).__name__}: "
                             f"{str(exc)[:120]}); see docs/bench-file.md") from None


def _parse_bench(raw: Mapping[str, Any], where: str, section: list) -> BenchConfig:
    """The bench file's sections, each by its own parser, then the checks across them."""
    if not isinstance(raw, Mapping):
        raise BenchFileError(f"{where}: expected a table at the top level")
    check_version(raw, where, fail=BenchFileError)  # optional top-level version: missing = 1
    raw = {k: v for k, v in raw.items() if k != "version"}
    unknown = sorted(set(raw) - _TOP)
    if unknown:
        raise BenchFileError(f"{where}: unknown top-level key(s) {unknown}; known: {sorted(_TOP)}")
    name, source, session = _bench_section(raw.get("bench"), where)
    geo = _geometry_section(raw.get("geometry"), where)
    ccd = _ccd_section(raw.get("ccd"), where)
    run = _run_section(raw.get("run"), where)
    instruments = _instruments_section(raw.get("instruments"), where, geo, run, section)
    procedures = _procedures_section(raw.get("procedure"), where, geo, section)
    cfg = BenchConfig(None, dict(raw), name, source, geo, run, instruments, procedures, ccd=ccd, session=session)
    if any(p["type"] == "ccd_sweep" for p in procedures) and ccd is None:
        raise BenchFileError(f"{where}: a ccd_sweep procedure needs the [ccd] section (position, tangential, "
                             f"reference_px: the camera's geometry for the dataset manifest)")
    for k, p in enumerate(procedures):  # every instrument a procedure reads must exist
        for inst in _proc_instruments(p):
            if inst not in instruments:
                raise _fail(where, f"procedure[{k}]", f"instrument {inst!r} to be defined in [instruments]",
                            sorted(instruments))
    return cfg


def _bench_section(node: Any, where: str) -> tuple[str, str, str | None]:
    """[bench]: (name, source, session)."""
    bench = _table(node, where, "bench", _BENCH)
    name = bench.get("name", Path(where).stem)
    if not isinstance(name, str) or not name:
        raise _fail(where, "bench.name", "a non-empty string", name)
    source = bench.get("source", "hardware")
    if source not in SOURCES:
        raise _fail(where, "bench.source", f"one of {SOURCES}", source)
    session = bench.get("session")
    if session is not None and not (isinstance(session, str) and len(session) == 32
                                    and all(c in "0123456789abcdef" for c in session)):
        raise _fail(where, "bench.session", "32 lower-case hex characters (the emulator session's uuid4)", session)
    return name, source, session


#: [geometry]'s optional single quantities: key -> (dimension, manifest key, its unit in SI). The
#: autocollimator's datasheet resolution and maximum error are GUM type B inputs of Hsieh's budget
#: (sec. 3.3 (2), (4)), declared in the manifest like the encoder's resolution.
_GEOMETRY_QUANTITIES: dict[str, tuple[str, str, float]] = {
    "encoder_resolution": ("angle", "encoder_resolution_arcsec", ARCSEC),
    "autocollimator_resolution": ("angle", "autocollimator_resolution_arcsec", ARCSEC),
    "autocollimator_accuracy": ("angle", "autocollimator_accuracy_arcsec", ARCSEC),
}


def _geometry_section(node: Any, where: str) -> dict[str, Any]:
    """[geometry]: the dataset manifest's ``bench`` (units in the key names)."""
    g = _table(node, where, "geometry", set(_GEOMETRY))
    for k in _GEOMETRY_REQUIRED:
        if k not in g:
            raise BenchFileError(f"{where}: [geometry]: missing key '{k}' (expected "
                                 f"{'an integer' if _GEOMETRY[k] is None else f'a quantity of dimension {_GEOMETRY[k]}'})")
    geo: dict[str, Any] = {
        "optical_radius_mm": _fmt(_q(g["optical_radius"], "length", where, "geometry.optical_radius") * 1e3),
        "L1_mm": _fmt(_q(g["L1"], "length", where, "geometry.L1") * 1e3),
        "L2_mm": _fmt(_q(g["L2"], "length", where, "geometry.L2") * 1e3),
        "grating_period_um": _fmt(_q(g["grating_period"], "length", where, "geometry.grating_period") * 1e6),
        "polygon_faces": _int(g["polygon_faces"], where, "geometry.polygon_faces", 3),
    }
    if not 0 <= geo["L1_mm"] < geo["L2_mm"]:
        raise _fail(where, "geometry.L1/L2", "0 <= L1 < L2", (g["L1"], g["L2"]))
    if "heads" in g:
        if not isinstance(g["heads"], list) or not g["heads"]:
            raise _fail(where, "geometry.heads", "a list of angles from head 1 (first '0 deg')", g["heads"])
        geo["heads_deg"] = [_fmt(_q(h, "angle", where, f"geometry.heads[{i}]") / DEG) for i, h in enumerate(g["heads"])]
        if geo["heads_deg"][0] != 0.0:
            raise _fail(where, "geometry.heads", "azimuths from head 1, so the first is '0 deg'", g["heads"])
    if "encoder_lines" in g:
        geo["encoder_lines"] = _int(g["encoder_lines"], where, "geometry.encoder_lines", 1)
    for k, (dim, out_key, unit) in _GEOMETRY_QUANTITIES.items():
        if k in g:
            geo[out_key] = _fmt(_q(g[k], dim, where, f"geometry.{k}") / unit)
    if "polygon_certificate" in g:
        cert = g["polygon_certificate"]
        if not isinstance(cert, list) or len(cert) != geo["polygon_faces"]:
            raise _fail(where, "geometry.polygon_certificate", f"{geo['polygon_faces']} angles (one per face)", cert)
        geo["polygon_certificate_arcsec"] = [_fmt(_q(c, "angle", where, f"geometry.polygon_certificate[{i}]") / ARCSEC)
                                             for i, c in enumerate(cert)]
    if "scale_edge_radius" in g:
        geo["scale_edge_radius_mm"] = _fmt(_q(g["scale_edge_radius"], "length", where, "geometry.scale_edge_radius") * 1e3)
    return geo


#: [run]: its keys (benchtwin.schema's declarative spec) and their defaults
RUN_KEYS: dict[str, Key] = {
    "waits": Key("str", choices=("real", "skip"), doc="real: Wait really waits; skip: it does not"),
    "driver_sleep_scale": Key("float", lo=0.0, doc="the drivers' sleeps (backoff, polls) scaled by this"),
    "theta": Key("str", choices=("target", "encoder"), doc="the tables' theta_deg: the commanded stop or the display"),
    "strict": Key("bool", doc="a reading whose status is not ok stops the run"),
    "stage": Key("str", doc="the stage's instrument table"),
    "fsync": Key("bool", doc="fsync every journal line"),
}
_RUN_DEFAULTS: dict[str, Any] = {"waits": "real", "driver_sleep_scale": 1.0, "theta": "target", "strict": True,
                                 "stage": "stage", "fsync": True}


def _run_section(node: Any, where: str) -> dict[str, Any]:
    """[run] (optional): its keys checked by ``RUN_KEYS``, the defaults filled in."""
    r = _table(node, where, "run", set(RUN_KEYS), required=False)
    check_table(r, RUN_KEYS, where, "[run]", fail=BenchFileError)
    return {**_RUN_DEFAULTS, **r}


def _instruments_section(node: Any, where: str, geo: Mapping[str, Any], run: Mapping[str, Any],
                         section: list) -> dict[str, dict[str, Any]]:
    """[instruments.*]: every instrument table, the run's stage a Zaber stage, and every closed-loop
    encoder an instrument of the file."""
    insts = _table(node, where, "instruments")
    if not insts:
        raise BenchFileError(f"{where}: [instruments]: expected at least one instrument table")
    instruments = {}
    for n, sec in insts.items():
        section[0] = f"[instruments.{n}]"
        instruments[n] = _instrument(n, sec, where, geo)
    section[0] = "the top level"
    if run["stage"] not in instruments:
        raise _fail(where, "run.stage", f"the name of an instrument table (have {sorted(instruments)})", run["stage"])
    if instruments[run["stage"]]["driver"] != "zaber":
        raise _fail(where, f"instruments.{run['stage']}.driver", "a stage driver ('zaber')",
                    instruments[run["stage"]]["driver"])
    for n, sec in instruments.items():
        enc = sec.get("closed_loop_encoder")
        if enc is not None and enc not in instruments:
            raise _fail(where, f"instruments.{n}.closed_loop_encoder", f"an instrument name (have {sorted(instruments)})", enc)
    return instruments


def _procedures_section(node: Any, where: str, geo: Mapping[str, Any], section: list) -> list[dict[str, Any]]:
    """[[procedure]]: at least one table, each in the procedure language."""
    if not isinstance(node, list) or not node:
        raise BenchFileError(f"{where}: missing [[procedure]] tables (expected at least one, type one of {PROCEDURES})")
    procedures = []
    for k, p in enumerate(node):
        section[0] = f"procedure[{k}]"
        procedures.append(_procedure(k, p, where, geo))
    section[0] = "the top level"
    return procedures


def _ccd_section(node: Any, where: str) -> dict[str, Any] | None:
    if node is None:
        return None
    c = _table(node, where, "ccd", set(_CCD))
    for k in ("position", "tangential", "reference_px"):
        if k not in c:
            raise BenchFileError(f"{where}: [ccd]: missing key '{k}'")
    out: dict[str, Any] = {"position_deg": _fmt(_q(c["position"], "angle", where, "ccd.position") / DEG), "outward": "+x"}
    if c["tangential"] not in ("+x", "-x"):
        raise _fail(where, "ccd.tangential", "'+x' or '-x' (the lab axis along image +y)", c["tangential"])
    out["tangential"] = c["tangential"]
    ref = c["reference_px"]
    if (not isinstance(ref, list) or len(ref) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in ref)):
        raise _fail(where, "ccd.reference_px", "[x, y] in pixels (numbers)", ref)
    out["reference_px"] = [float(v) for v in ref]
    if "pixel_size" in c:
        out["pixel_um"] = _fmt(_q(c["pixel_size"], "length", where, "ccd.pixel_size") * 1e6)
    return out


def _instrument(name: str, sec: Any, where: str, geo: Mapping[str, Any]) -> dict[str, Any]:
    """[instruments.NAME]: driver and port, then a camera's or a serial instrument's keys."""
    at = f"instruments.{name}"
    s = _table(sec, where, at, _INSTRUMENT)
    drv = s.get("driver")
    if drv not in DRIVERS:
        raise _fail(where, f"{at}.driver", f"one of {sorted(DRIVERS)}", drv)
    port = s.get("port")
    if not isinstance(port, str) or not port:
        raise _fail(where, f"{at}.port", "a port name, pseudo-terminal path or pyserial URL (string)"
                    + ("; for a camera its folder or VideoCapture source" if drv in CAMERA_DRIVERS else ""), port)
    out: dict[str, Any] = {"driver": drv, "port": port}
    if drv in CAMERA_DRIVERS:
        return _camera_instrument(s, out, where, at)
    return _serial_instrument(s, out, where, at, geo)


def _camera_instrument(s: Mapping[str, Any], out: dict[str, Any], where: str, at: str) -> dict[str, Any]:
    """A camera (not serial): only its options."""
    drv = out["driver"]
    for k in ("serial", "commands", "backoff", "reconnect", "retries"):
        if k in s:
            raise BenchFileError(f"{where}: [{at}]: key '{k}' is for serial instruments, not camera driver {drv!r}")
    out.update(serial={}, commands={}, retries=0, backoff_s=0.0, reconnect=False,
               options=_table(s.get("options", {}), where, f"{at}.options"))
    for k in ("soft_limits", "max_speed", "closed_loop_encoder", "heads"):
        if k in s:
            raise BenchFileError(f"{where}: [{at}]: key '{k}' is not for a camera")
    return out


def _serial_instrument(s: Mapping[str, Any], out: dict[str, Any], where: str, at: str,
                       geo: Mapping[str, Any]) -> dict[str, Any]:
    """A serial instrument: port settings, options, commands, retries, backoff, reconnect; the
    stage's (Zaber) and the encoder's (Heidenhain) own keys."""
    drv = out["driver"]
    out["serial"] = _table(s.get("serial", {}), where, f"{at}.serial", _SERIAL)
    out["options"] = _table(s.get("options", {}), where, f"{at}.options")
    out["commands"] = _table(s.get("commands", {}), where, f"{at}.commands")
    out["retries"] = _int(s.get("retries", 2), where, f"{at}.retries", 0)
    out["backoff_s"] = _q(s.get("backoff", "0.05 s"), "time", where, f"{at}.backoff")
    out["reconnect"] = s.get("reconnect", True)
    if not isinstance(out["reconnect"], bool):
        raise _fail(where, f"{at}.reconnect", "true or false", out["reconnect"])
    if drv == "zaber":
        _zaber_keys(s, out, where, at)
    else:
        for k in ("soft_limits", "max_speed", "closed_loop_encoder"):
            if k in s:
                raise BenchFileError(f"{where}: [{at}]: key '{k}' is for the stage (driver 'zaber') only")
    if drv == "heidenhain":
        if "heads" in s:
            out["options"]["heads_deg"] = [_fmt(_q(h, "angle", where, f"{at}.heads[{i}]") / DEG)
                                           for i, h in enumerate(s["heads"])]
        elif "heads_deg" not in out["options"] and "heads_deg" in geo:
            out["options"]["heads_deg"] = list(geo["heads_deg"])
    elif "heads" in s:
        raise BenchFileError(f"{where}: [{at}]: key 'heads' is for the encoder (driver 'heidenhain') only")
    return out


def _zaber_keys(s: Mapping[str, Any], out: dict[str, Any], where: str, at: str) -> None:
    """The stage's keys: soft limits, speed limit, microsteps, closed-loop encoder."""
    lim = s.get("soft_limits")
    if not isinstance(lim, list) or len(lim) != 2:
        raise _fail(where, f"{at}.soft_limits", "[low, high] angles, e.g. ['-5 deg', '365 deg']", lim)
    lo, hi = (_q(v, "angle", where, f"{at}.soft_limits") / DEG for v in lim)
    if not lo < hi:
        raise _fail(where, f"{at}.soft_limits", "low < high", lim)
    out["soft_limits_deg"] = (_fmt(lo), _fmt(hi))
    if "max_speed" not in s:
        raise BenchFileError(f"{where}: [{at}]: missing key 'max_speed' (expected an angular speed, e.g. '20 deg/s')")
    out["max_speed_deg_s"] = _fmt(_q(s["max_speed"], "angular_speed", where, f"{at}.max_speed") / DEG)
    if "microsteps_per_deg" not in out["options"]:
        raise BenchFileError(f"{where}: [{at}.options]: missing key 'microsteps_per_deg' (a number, from the "
                             f"stage's datasheet)")
    out["closed_loop_encoder"] = s.get("closed_loop_encoder")


def _procedure(k: int, p: Any, where: str, geo: Mapping[str, Any]) -> dict[str, Any]:
    """[[procedure]] number ``k``: its type's keys (``procedures.PROCEDURE_PARAMS``), the polygon's
    faces and the heads from [geometry] when it does not give them."""
    at = f"procedure[{k}]"
    if not isinstance(p, Mapping):
        raise _fail(where, at, "a table", p)
    typ = p.get("type")
    if typ not in _PROC_KEYS:
        raise _fail(where, f"{at}.type", f"one of {PROCEDURES}", typ)
    spec = _PROC_KEYS[typ]
    unknown = sorted(set(p) - set(spec) - {"type"})
    if unknown:
        raise BenchFileError(f"{where}: [{at}] ({typ}): unknown key(s) {unknown}; known: {sorted(spec)}")
    out: dict[str, Any] = {"type": typ}
    for key, kind in spec.items():
        if key in p:
            out[key] = _procedure_value(key, kind, p[key], where, f"{at}.{key}")
    if "faces" not in out and typ.startswith("polygon"):
        out["faces"] = int(geo["polygon_faces"])
    if typ == "selfcal" and "heads" not in out:
        out["heads"] = list(geo.get("heads_deg", [0.0]))
    return out


def _procedure_value(key: str, kind: Any, v: Any, where: str, kk: str) -> Any:
    """One procedure key's value checked against its kind (int, bool, str, list, angle(s), time)."""
    if kind is int:
        return _int(v, where, kk, 0 if key == "rep" else 1)
    if kind is bool:
        if not isinstance(v, bool):
            raise _fail(where, kk, "true or false", v)
        return v
    if kind is str:
        if not isinstance(v, str):
            raise _fail(where, kk, "an instrument name (string)", v)
        return v
    if kind is list:
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise _fail(where, kk, "a list of strings", v)
        if key == "directions" and not set(v) <= {"forward", "backward"}:
            raise _fail(where, kk, "a list of 'forward'/'backward'", v)
        return list(v)
    if kind == "angles":
        if not isinstance(v, list) or not v:
            raise _fail(where, kk, "a list of angles", v)
        return [_fmt(_q(x, "angle", where, kk) / DEG) for x in v]
    if kind == "angle":
        return _fmt(_q(v, "angle", where, kk) / DEG)
    if kind == "time":
        return _q(v, "time", where, kk)
    raise AssertionError(f"procedure key {key!r}: unknown kind {kind!r}")


def _proc_instruments(p: Mapping[str, Any]) -> list[str]:
    typ = p["type"]
    if typ == "radial_motion":
        return [p.get("encoder", "encoder"), *p.get("probes", ["probe_top", "probe_bottom"])]
    if typ.startswith("polygon"):
        return [p.get("encoder", "encoder"), p.get("autocollimator", "autocollimator")]
    if typ == "ccd_sweep":
        return [p.get("encoder", "encoder"), p.get("camera", "ccd")]
    return [p.get("encoder", "encoder")]


# --------------------------------------------------------------------------- procedures

def build_procedure(cfg: BenchConfig) -> list:
    """All ``[[procedure]]`` tables, in order, as one list of steps (a dry run; ``acquire`` uses
    ``iter_procedure``, which yields the same steps lazily)."""
    return list(iter_procedure(cfg))


def iter_procedure(cfg: BenchConfig) -> Iterator:
    """The steps of every ``[[procedure]]`` table, in order, generated lazily (flat memory)."""
    return P.steps_from_specs(cfg.procedures)


# --------------------------------------------------------------------------- instruments

def _driver_class(name: str) -> Any:
    mod, cls = DRIVERS[name]
    return getattr(importlib.import_module(mod), cls)


def open_instruments(cfg: BenchConfig, *, sleep: Callable[[float], None] | None = None,
                     clock: Callable[[], float] | None = None,
                     open_port: Callable[..., Any] | None = None) -> tuple[dict[str, Any], list]:
    """Open every port and build the drivers: ``({name: driver}, [open SharedPort])`` (the stage is
    built last, so its closed-loop encoder exists). ``open_port(spec, **settings)`` defaults to
    ``open_transport``; close with ``close_instruments(ports)``."""
    from benchtwin.hw.drivers.base import SharedPort
    from benchtwin.hw.transport import open_transport, reopener

    opener = open_port or open_transport
    shared: dict[str, Any] = {}
    out: dict[str, Any] = {}
    order = sorted(cfg.instruments, key=lambda n: cfg.instruments[n]["driver"] == "zaber")
    where = str(cfg.path or "<bench>")
    try:
        for name in order:
            sec = cfg.instruments[name]
            cls = _driver_class(sec["driver"])
            if sec["driver"] in CAMERA_DRIVERS:
                out[name] = _open_camera(cls, name, sec, where, clock)
                continue
            settings = cls.serial_settings(**sec["serial"])
            if sec["port"] not in shared:
                try:
                    shared[sec["port"]] = (SharedPort(opener(sec["port"], **settings)), settings)
                except Exception as exc:  # serial.SerialException, OSError, ValueError
                    raise BenchFileError(f"{where}: key 'instruments.{name}.port': cannot open {sec['port']!r}: "
                                         f"{exc}") from exc
            port, port_settings = shared[sec["port"]]
            kw: dict[str, Any] = dict(sec["options"])
            kw.update(commands=sec["commands"] or None, retries=sec["retries"], backoff_s=sec["backoff_s"],
                      sleep=sleep, clock=clock)
            if sec["reconnect"] and open_port is None:
                kw["reconnect"] = reopener(sec["port"], **port_settings)
            if sec["driver"] == "zaber":
                kw.update(soft_limits_deg=sec["soft_limits_deg"], max_speed_deg_s=sec["max_speed_deg_s"])
                if sec.get("closed_loop_encoder"):
                    kw["encoder"] = out[sec["closed_loop_encoder"]]
            try:
                out[name] = cls(name, port, **kw)
            except TypeError as exc:
                raise BenchFileError(f"{where}: [instruments.{name}.options]: {exc}") from None
            except ValueError as exc:
                raise BenchFileError(f"{where}: [instruments.{name}]: {exc}") from None
    except BaseException:
        close_instruments([p for p, _ in shared.values()])
        raise
    return out, [p for p, _ in shared.values()]


def _open_camera(cls: Any, name: str, sec: Mapping[str, Any], where: str, clock: Any) -> Any:
    """A camera driver (not serial): a watched folder polls with real sleeps (waiting for a file,
    not a device backoff, so ``driver_sleep_scale`` does not apply)."""
    kw: dict[str, Any] = dict(sec["options"])
    try:
        if sec["driver"] == "opencv":
            src: Any = int(sec["port"]) if sec["port"].isdigit() else sec["port"]
            return cls.open(name, src, clock=clock, **kw)
        return cls(name, sec["port"], clock=clock, **kw)
    except TypeError as exc:
        raise BenchFileError(f"{where}: [instruments.{name}.options]: {exc}") from None
    except ValueError as exc:
        raise BenchFileError(f"{where}: key 'instruments.{name}.port': {exc}") from None


def close_instruments(ports: list) -> None:
    """Close the ports ``open_instruments`` opened (best effort)."""
    for p in ports:
        try:
            p.transport.close()
        except Exception:  # noqa: BLE001 - closing is best effort
            pass


# --------------------------------------------------------------------------- manifest

def dataset_manifest(cfg: BenchConfig, instruments: Mapping[str, Any] | None = None) -> dict[str, Any]:
    m: dict[str, Any] = {"format": "bench-dataset", "version": 1, "source": cfg.source,
                         "bench_name": cfg.name, "created_by": "benchtwin.hw.acquisition.acquire",
                         "bench": dict(cfg.geometry)}
    if cfg.ccd is not None:
        m["ccd"] = dict(cfg.ccd)
    if instruments:
        m["instruments"] = {n: {k: v for k, v in d.describe().items() if k in ("kind", "model", "units", "serial")}
                            for n, d in instruments.items()}
    return m
