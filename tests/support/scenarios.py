"""The small scenarios the twin tests simulate, and a folder's bytes."""

from __future__ import annotations

from pathlib import Path

from benchtwin.twin.scenario import Scenario, load_scenario, validate

ROOT = Path(__file__).resolve().parents[2]
HIDDEN_DIR = ROOT / "scenarios" / "hidden"

# A small jia2019 bench (tests/twin/test_simulate.py and the tests that reuse its dataset).
SMALL = {
    "procedure.radial_reps": 2,
    "procedure.radial_positions": 24,
    "procedure.ccd_step": "90 deg",
    "procedure.polygon_shifts": ["0 deg", "5 deg"],
    "procedure.selfcal": True,
    "procedure.selfcal_step": "30 deg",
    "procedure.directions": ["forward", "backward"],
    "bench.heads": ["0 deg", "120 deg", "240 deg"],
    "bench.polygon_faces": 8,
    "instruments.ccd.width": "128 px",
    "instruments.ccd.height": "96 px",
    "instruments.autocollimator.accuracy": "0 arcsec",
    "instruments.autocollimator.noise": "0 arcsec",
    "errors.graduation_error_rms": "0.5 arcsec",
    # rolling-path bearings with the waviness and rep-wise non-repeating motion jia2019.toml had
    # before its ball sets: these tests check the instruments' equations against the truth α grid,
    # which a ball bench's path-dependent asynchronous motion (tests/twin/test_bearing.py) would blur
    "bearings.type": "path",
    "bearings.waviness_top": [{"order": 2, "amplitude": "0.15 um", "phase": "30 deg"},
                              {"order": 3, "amplitude": "0.10 um", "phase": "110 deg"}],
    "bearings.waviness_bottom": [{"order": 2, "amplitude": "0.10 um", "phase": "250 deg"}],
    "bearings.async_rms": "0.06 um",
}

# A smaller bench for the hidden-effect datasets (tests/twin/test_hidden.py, test_truth_leak.py).
HIDDEN_SMALL = {"procedure.radial_reps": 1, "procedure.radial_positions": 24, "procedure.ccd_step": "180 deg",
                "bench.polygon_faces": 8, "instruments.ccd.width": "128 px", "instruments.ccd.height": "96 px"}


def small_scenario(**extra) -> Scenario:
    """jia2019 reduced by ``SMALL``, with ``extra`` overrides on top."""
    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides({**SMALL, **extra})


def load_hidden(name: str) -> Scenario:
    """scenarios/hidden/NAME.toml."""
    return load_scenario(HIDDEN_DIR / f"{name}.toml")


def without_hidden(sc: Scenario) -> Scenario:
    """The scenario with its [hidden] table removed."""
    raw = dict(sc.raw)
    raw.pop("hidden", None)
    return validate(raw, f"{sc.name} without [hidden]")


def files(d: Path) -> dict[str, bytes]:
    """Every file under ``d``, by its path relative to ``d``: its bytes."""
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}
