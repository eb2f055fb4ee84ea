"""A bench file's raw tables, as tomllib reads them (hardware-in-the-loop and fuzz tests)."""

from __future__ import annotations

from pathlib import Path


def bench_raw(**over) -> dict:
    """A valid bench file on loop:// ports; ``section__key=value`` replaces a key, ``None`` removes it."""
    raw = {"bench": {"name": "b", "source": "hardware"},
           "geometry": {"optical_radius": "22 mm", "L1": "6.81 mm", "L2": "122.96 mm", "grating_period": "20 um",
                        "polygon_faces": 23, "heads": ["0 deg"]},
           "instruments": {"encoder": {"driver": "heidenhain", "port": "loop://"},
                           "autocollimator": {"driver": "elcomat", "port": "loop://"},
                           "stage": {"driver": "zaber", "port": "loop://", "soft_limits": ["-1 deg", "361 deg"],
                                     "max_speed": "20 deg/s", "options": {"microsteps_per_deg": 1000}}},
           "procedure": [{"type": "polygon_traditional", "start_face": 2, "dwell": "0.1 s"}]}
    for k, v in over.items():
        sec, key = k.split("__")
        if v is None:
            raw[sec].pop(key)
        else:
            raw[sec][key] = v
    return raw


def loop_bench_file(tmp_path: Path) -> Path:
    """``tmp_path/b.toml``: an emulated bench on loop:// ports with one polygon procedure, no waits and
    short timeouts (the acquisition tests of the writing rule and of reliability)."""
    p = tmp_path / "b.toml"
    p.write_text(
        '[bench]\nname = "b"\nsource = "emulated"\n'
        '[geometry]\noptical_radius = "22 mm"\nL1 = "6.81 mm"\nL2 = "122.96 mm"\ngrating_period = "20 um"\n'
        'polygon_faces = 4\nheads = ["0 deg"]\n'
        '[run]\nwaits = "skip"\ndriver_sleep_scale = 0\n'
        '[instruments.encoder]\ndriver = "heidenhain"\nport = "loop://"\nretries = 0\nserial = { timeout = 0.05 }\n'
        '[instruments.autocollimator]\ndriver = "elcomat"\nport = "loop://"\nretries = 0\nserial = { timeout = 0.05 }\n'
        '[instruments.stage]\ndriver = "zaber"\nport = "loop://"\nsoft_limits = ["-1 deg", "361 deg"]\n'
        'max_speed = "20 deg/s"\nretries = 0\nserial = { timeout = 0.05 }\noptions = { microsteps_per_deg = 1000 }\n'
        '[[procedure]]\ntype = "polygon_traditional"\nstart_face = 1\ndwell = "0.1 s"\n')
    return p
