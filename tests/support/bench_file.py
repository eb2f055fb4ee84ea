"""A bench file's raw tables, as tomllib reads them (hardware-in-the-loop and fuzz tests)."""

from __future__ import annotations


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
