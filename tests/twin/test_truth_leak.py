"""Truth never leaks (issue 15 item 7; principle 3): no file a dataset writes outside truth/
(manifest, tables, CCD index and images, journal) holds a true value.

Two independent checks on a small dataset with many hidden effects at once (every one a true
value the dataset must not declare):

1. differential: against the same scenario without [hidden], every non-truth file is identical
   except where the physics shows in the readings (the instruments' reading columns, the journal's
   readings and move results, the CCD pixels);
2. numeric: no number of ≥ 8 significant digits in a non-truth text file equals (to 1e-9) a number
   that exists only in truth/ (a true parameter, pose, centre, pixel size, graduation map, ...),
   in SI or in the units a dataset uses (µm, arcsec, deg, mm).
"""

from __future__ import annotations

import csv
import json
import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from benchtwin.twin.scenario import validate
from benchtwin.twin.simulate import simulate
from benchtwin.units import ARCSEC

from tests.support.scenarios import HIDDEN_SMALL as SMALL
from tests.support.scenarios import load_hidden as load
from tests.support.scenarios import without_hidden

# Hidden effects with distinct true values (SI), all at once.
HIDDEN = {
    "graduation_error": {"orders": [4], "amplitudes": ["0.8 arcsec"], "phases": ["35 deg"],
                         "ruling_walk_rms": "0.3 arcsec", "ruling_eccentricity": "1.3 um",
                         "ruling_eccentricity_azimuth": "33 deg"},
    "ac_scale": {"focal_length_error": 0.0031, "detector_tilt": "0.7 deg", "distortion_k1": 40.0},
    "ac_drift": {"rate": "0.37 arcsec/h"},
    "optical_radius": {"relative": 0.0123},
    "tilt_abbe": {"delta_L1": "0.77 mm"},
    "ccd_pixel_scale": {"pixel_relative": 0.0021, "grating_period_relative": 0.0017},
    "thermal_growth": {"order": 7, "phase": "80 deg", "cte_mismatch": "15 ppm/K", "hub_radius": "10 mm"},
    "sphere_form": {"top": [{"order": 3, "amplitude": "0.11 um", "phase": "21 deg"}]},
}
# Columns (and journal fields) that are readings: where the hidden physics is allowed to show.
READING_COLUMNS = {"ac_arcsec", "ac_y_arcsec", "theta_read_deg", "t_s", "probe_top_um", "probe_bottom_um",
                   "probe_top_x_um", "probe_bottom_x_um"}
_NUM = re.compile(r"[-+]?\d+\.\d+(?:[eE][-+]?\d+)?|[-+]?\d+[eE][-+]?\d+")


def _files(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("leak")
    raw = dict(load("graduation_error").raw)
    raw["hidden"] = HIDDEN
    raw["thermal"] = {"motor_rise": "5 K", "motor_time_constant": "2 min", "structure_time_constant": "3 min"}
    sc = validate(raw, "leak test").with_overrides({**SMALL, "instruments.ccd.width": "256 px",
                                                     "instruments.ccd.height": "192 px"})
    hid = simulate(sc, base / "hidden", progress=False, backend="analytic")
    plain = simulate(without_hidden(sc), base / "plain", progress=False, backend="analytic")
    again = simulate(sc, base / "again", progress=False, backend="analytic")
    assert _files(hid) == _files(again)    # same seed, same dataset (the new physics included)
    return hid, plain


def _csv_rows(b: bytes) -> list[dict]:
    return list(csv.DictReader(b.decode().splitlines()))


def test_outside_truth_only_the_readings_change(runs):
    hid, plain = runs
    fh, fp = _files(hid), _files(plain)
    outside = sorted(k for k in fh if not k.startswith("truth/"))
    assert outside == sorted(k for k in fp if not k.startswith("truth/"))
    changed = set()
    for name in outside:
        a, b = fh[name], fp[name]
        if a == b:
            continue
        changed.add(name)
        if name.endswith(".csv"):
            ra, rb = _csv_rows(a), _csv_rows(b)
            assert len(ra) == len(rb) and list(ra[0]) == list(rb[0]), name
            for x, y in zip(ra, rb):
                for col in x:
                    if col not in READING_COLUMNS:
                        assert x[col] == y[col], f"{name}: column {col} changed with the hidden truth"
        elif name.endswith(".jsonl"):
            la, lb = a.decode().splitlines(), b.decode().splitlines()
            assert len(la) == len(lb)
            for x, y in zip(la, lb):
                jx, jy = json.loads(x), json.loads(y)
                for j in (jx, jy):
                    j.pop("t_s", None)
                    j.pop("result", None)
                    if "row" in j:
                        j["row"].pop("readings", None)
                        j["row"].pop("reading", None)
                        j["row"].pop("t_s", None)
                assert jx == jy, f"{name}: a journal entry changed outside its readings: {x[:200]}"
        elif name.endswith(".png"):
            continue   # pixels are readings (the hidden CCD scale shows in them); metadata below
        else:
            pytest.fail(f"{name} changed with the hidden truth")
    assert "manifest.json" not in changed
    assert "polygon.csv" in changed and "radial_motion.csv" in changed   # the physics does show


def _is_time(key: str) -> bool:
    """The bench clock's times are readings (every table has t_s), not secrets."""
    return key == "t_s" or key.endswith("_t_s") or key in ("t_end_s", "duration_s")


def _numbers(x, out: list) -> None:
    if isinstance(x, bool):
        return
    if isinstance(x, float):
        out.append(x)
    elif isinstance(x, dict):
        for k, v in x.items():
            if not _is_time(str(k)):
                _numbers(v, out)
    elif isinstance(x, list):
        for v in x:
            _numbers(v, out)


def _sig_digits(tok: str) -> int:
    m = tok.lstrip("+-").split("e")[0].split("E")[0].replace(".", "").lstrip("0")
    return len(m.rstrip("0")) if m else 0


def _png_text(b: bytes) -> bytes:
    out, i = b"", 8
    while i + 8 <= len(b):
        n, t = struct.unpack(">I4s", b[i:i + 8])
        if t in (b"tEXt", b"iTXt", b"zTXt", b"eXIf"):
            out += b[i + 8:i + 8 + n] + b"\n"
        i += 12 + n
    return out


def _leaks(fh: dict[str, bytes], declared_manifest: bytes) -> list[tuple[str, str]]:
    """(file, token) of every number outside truth/ of the dataset ``fh`` that equals a truth-only
    value; ``declared_manifest``: the manifest of the same scenario without [hidden] (what the
    dataset may declare)."""
    truth_vals: list[float] = []
    for name, b in fh.items():
        if not name.startswith("truth/"):
            continue
        if name.endswith(".json"):
            if name == "truth/scenario.json":
                continue    # the declared scenario (+ [hidden] in SI): checked by the declared set below
            _numbers(json.loads(b), truth_vals)
        elif name.endswith(".csv"):
            for row in _csv_rows(b):
                for k, v in row.items():
                    if k in ("theta_deg", "target_deg") or _is_time(k) or not v:
                        continue   # commanded / held stops are procedure values, in the dataset too
                    try:
                        truth_vals.append(float(v))
                    except ValueError:
                        pass
    # the declared scenario's values are not secrets (the manifest declares them)
    declared: list[float] = []
    _numbers(json.loads(declared_manifest), declared)
    dec = np.array(declared)
    vals = np.array([v for v in truth_vals if math.isfinite(v) and v != 0.0])
    units = np.stack([vals, vals / ARCSEC, np.degrees(vals), vals * 1e6, vals * 1e3])
    if dec.size:
        # a value the manifest declares in one unit is declared in all: the encoder's 0.39″ count
        # (declared in arcsec) is also 0.000108333…°, the display reading of a stop at 0° that
        # holds the count above it
        declared_v = np.isclose(units[:, :, None], dec[None, None, :], rtol=1e-9, atol=0).any(axis=(0, 2))
        units = units[:, ~declared_v]
    conv = units.ravel()
    conv = conv[np.abs(conv) > 1e-300]
    secrets = np.sort(conv)
    leaks = []
    for name, b in fh.items():
        if name.startswith("truth/"):
            continue
        text = (_png_text(b) if name.endswith(".png") else b).decode("utf-8", "replace")
        for tok in _NUM.findall(text):
            if _sig_digits(tok) < 8:
                continue
            x = float(tok)
            if x == 0.0 or math.isclose(float(f"{x:.4g}"), x, rel_tol=1e-12):
                continue   # a round number (26.000000000000007 s) in float dress: no evidence
            i = np.searchsorted(secrets, x)
            for j in (i - 1, i):
                if 0 <= j < secrets.size and math.isclose(secrets[j], x, rel_tol=1e-9):
                    leaks.append((name, tok))
    return leaks


def test_no_true_value_in_any_file_outside_truth(runs):
    hid, plain = runs
    leaks = _leaks(_files(hid), (plain / "manifest.json").read_bytes())
    assert not leaks, f"true values outside truth/: {leaks[:10]} ({len(leaks)} in all)"


def test_the_leak_scan_finds_a_planted_true_value(runs):
    """The scan is not blind: a true value written into the journal (as the old journal.jsonl did
    with the frames' true disk centres) or the manifest, in another unit, is found."""
    hid, plain = runs
    fh, dm = _files(hid), (plain / "manifest.json").read_bytes()
    bench = json.loads(fh["truth/bench.json"])
    true_r = bench["instruments"]["encoder"]["optical_radius_m"]          # r·(1 + 0.0123)
    assert _leaks({**fh, "journal.jsonl": fh["journal.jsonl"] + b'{"radius_mm": %r}\n' % (true_r * 1e3)}, dm)
    m = json.loads(fh["manifest.json"])
    m["note"] = {"x": json.loads(fh["truth/hidden.json"])["thermal_growth"]["amplitude_rad_per_K"]}
    assert _leaks({**fh, "manifest.json": json.dumps(m).encode()}, dm)
    ccd = _csv_rows(fh["truth/ccd.csv"])
    row = f"9,0.0,x.png,{ccd[0]['centre_x_px']},1.0\n".encode()
    assert _leaks({**fh, "ccd/index.csv": fh["ccd/index.csv"] + row}, dm)
    assert not _leaks(fh, dm)
