"""The results of an analysis as a typed, read-only object (issue 34: a notebook API).

``benchtwin.analyze(dataset)`` returns a :class:`Results`: a read-only mapping of results.json's
keys (``res["eccentricity_um"]`` works as it did on the dict; the keys, units and meanings are
docs/results-format.md, generated from analysis/results.py) with named properties for the main
quantities and :meth:`Results.to_dataframe` for its curves. The object wraps the results exactly as
the pipeline built them; results.json is written from the same dict, so its bytes do not depend on
this class.

The main quantities, each with its unit and standard uncertainty (GUM, k = 1) unless stated:

- :attr:`Results.eccentricity`, :attr:`Results.theta0`: e and θ0 from the CCD images (Jia 2019 eqs. 10–12);
- :attr:`Results.calibration`: the encoder error curve a certificate states, with u, U = k·u, k, ν
  and what u includes (analysis/calibration.py);
- :attr:`Results.residual_before`, :attr:`Results.residual_after`: measured − Jia model (eq. 5), before
  and after the loop's traced effects (RMS, P-V, share of the error);
- :attr:`Results.identified_effects`: the effects the loop identified, with their parameters and u.

Curves for a table (:meth:`Results.curve` gives numpy arrays, :meth:`Results.to_dataframe` a pandas
DataFrame): see :data:`CURVES`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas

    from benchtwin.analysis.calibration import CalibrationCurve

__all__ = ["Results", "Quantity", "CURVES"]

#: the curves :meth:`Results.curve` / :meth:`Results.to_dataframe` give: name → (results.json key,
#: {column: key inside the section}); columns carry their unit in the name
CURVES: dict[str, tuple[str, dict[str, str]]] = {
    "encoder_error": ("encoder_error_arcsec", {"theta_deg": "theta_deg", "error_arcsec": "value", "u_arcsec": "u",
                                               "U_arcsec": "U"}),
    "encoder_error_corrected": ("encoder_error_corrected_arcsec", {"theta_deg": "theta_deg", "error_arcsec": "value",
                                                                   "u_arcsec": "u"}),
    "comparison": ("comparison", {"theta_deg": "theta_deg", "measured_arcsec": "measured_arcsec",
                                  "model_arcsec": "model_arcsec", "residual_arcsec": "residual_arcsec"}),
    "comparison_after": ("comparison_after", {"theta_deg": "theta_deg", "model_arcsec": "model_arcsec",
                                              "residual_arcsec": "residual_arcsec"}),
    "model_prediction": ("model_prediction_arcsec", {"theta_deg": "theta_deg", "model_arcsec": "value",
                                                     "u_arcsec": "u"}),
    "radial_motion": ("radial_motion", {"theta_deg": "theta_deg", "dY_um": "dY_um", "u_dY_um": "u_dY_theta_um",
                                        "tilt_x_urad": "tilt_x_urad"}),
    "ccd": ("ccd", {"theta_deg": "theta_deg", "d_ref_um": "d_ref_um"}),
}


@dataclass(frozen=True)
class Quantity:
    """A value with its standard uncertainty (GUM, k = 1) and unit."""

    value: float
    u: float
    unit: str

    def __str__(self) -> str:
        if not math.isfinite(self.u) or self.u <= 0:
            return f"{self.value:.6g} {self.unit}"
        digits = max(0, 1 - math.floor(math.log10(self.u)))   # u to two significant digits
        return f"{self.value:.{digits}f} ± {self.u:.{digits}f} {self.unit} (standard uncertainty)"


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


@dataclass(frozen=True, eq=False)
class Results(Mapping[str, Any]):
    """An analysis's results: a read-only mapping of results.json's keys with typed properties.

    ``data`` is the pipeline's dict (numpy arrays where results.json has lists);
    :meth:`to_json` gives what results.json holds, :meth:`read` reads a results.json back."""

    data: Mapping[str, Any]

    def __post_init__(self) -> None:
        # a copy of the top level (the object has no setter; a plain dict keeps it picklable)
        object.__setattr__(self, "data", dict(self.data.data if isinstance(self.data, Results) else self.data))

    # ------------------------------------------------------------------ the mapping (as the dict was)
    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    @classmethod
    def read(cls, path: str | Path) -> Results:
        """A results.json as written by analyze / close-loop (checked by ``read_results``)."""
        from benchtwin.analysis.results import read_results

        return cls(read_results(path))

    @classmethod
    def checked(cls, obj: Any, where: str = "results.json") -> Results:
        """A parsed results.json, checked by the format (``validate_results``: a ResultsError names
        ``where`` and the key)."""
        from benchtwin.analysis.results import validate_results

        return cls(validate_results(obj, where))

    @classmethod
    def parse(cls, text: str, where: str = "results.json") -> Results:
        """A results.json's text (already read as an input: ``read_results_text``), checked by the format."""
        from benchtwin.analysis.results import parse_results

        return cls(parse_results(text, where))

    def to_json(self) -> dict[str, Any]:
        """What results.json holds (plain lists, non-finite numbers as None)."""
        from benchtwin.jsonable import to_json

        out: dict[str, Any] = to_json(self.data, nonfinite="null", drop_callables=True)
        return out

    # ------------------------------------------------------------------ the main quantities
    @property
    def kind(self) -> str:
        """"bench" (a twin, emulator or bench dataset) or "error-curve" (an imported table)."""
        return str(self.data.get("kind") or "bench")

    @property
    def eccentricity(self) -> Quantity | None:
        """Installation eccentricity e (Jia eq. 11), µm, with u (the fit ⊕ the probes' asynchronous
        part, or type A from repeated sweeps: ``eccentricity_u_source``); None without CCD images."""
        if "eccentricity_um" not in self.data:
            return None
        return Quantity(_num(self.data["eccentricity_um"]), _num(self.data.get("eccentricity_u_um")), "µm")

    @property
    def theta0(self) -> Quantity | None:
        """Phase θ0 of the eccentricity (Jia eq. 12), degrees, with u; None without CCD images."""
        if "eccentricity_phase_deg" not in self.data:
            return None
        return Quantity(_num(self.data["eccentricity_phase_deg"]), _num(self.data.get("eccentricity_phase_u_deg")),
                        "deg")

    @property
    def calibration(self) -> CalibrationCurve | None:
        """The encoder error curve a certificate states, with u, U = k·u, k, ν and what u includes
        and excludes (analysis/calibration.py: the corrected curve when the loop applied a correction
        of the reference chain, else the measured one); None without an encoder error curve."""
        from benchtwin.analysis.calibration import calibration_curve

        return calibration_curve(self.data)

    @property
    def residual_before(self) -> Mapping[str, Any] | None:
        """Measured encoder error − Jia model (eq. 5): ``rms_arcsec``, ``pv_arcsec``,
        ``fraction_of_error``, ... (results-format.md, ResidualSummary); None without the comparison."""
        r = self.data.get("residual_before")
        return MappingProxyType(r) if r is not None else None

    @property
    def residual_after(self) -> Mapping[str, Any] | None:
        """The same after the loop's traced effects joined the model (close_loop=True); None without."""
        r = self.data.get("residual_after")
        return MappingProxyType(r) if r is not None else None

    @property
    def identified_effects(self) -> list[Mapping[str, Any]]:
        """The effects the loop identified: ``name``, ``params`` and their ``u`` (units in the
        parameter names), ``evidence``; [] when none (or the loop did not run)."""
        return [MappingProxyType(e) for e in self.data.get("identified_effects") or []]

    @property
    def effect_names(self) -> list[str]:
        return [str(e["name"]) for e in self.identified_effects]

    @property
    def notes(self) -> list[str]:
        """The analysis's assumptions and warnings, in words."""
        return [str(n) for n in self.data.get("notes") or []]

    # ------------------------------------------------------------------ curves
    def curves(self) -> list[str]:
        """The names of the curves these results hold (see :data:`CURVES`, and "calibration")."""
        names = [n for n, (key, _) in CURVES.items() if isinstance(self.data.get(key), Mapping)]
        return (["calibration"] if self.calibration is not None else []) + names

    def curve(self, name: str = "calibration") -> dict[str, np.ndarray]:
        """One curve as numpy arrays, one per column (the unit in each name); no pandas needed.

        ``"calibration"``: ``theta_deg, error_arcsec, u_arcsec, U_arcsec, k`` as calibration.csv
        has them (unrounded); the other names: :data:`CURVES`. A KeyError names the curves there are."""
        if name == "calibration":
            c = self.calibration
            if c is None:
                raise KeyError(f"no calibration curve in these results; curves: {', '.join(self.curves()) or 'none'}")
            return {"theta_deg": np.asarray(c.theta_deg, dtype=float), "error_arcsec": np.asarray(c.error_arcsec),
                    "u_arcsec": np.asarray(c.u_arcsec), "U_arcsec": np.asarray(c.U_arcsec),
                    "k": np.full(len(c.theta_deg), c.k)}
        if name not in CURVES:
            raise KeyError(f"unknown curve {name!r}; expected one of calibration, {', '.join(CURVES)}")
        key, cols = CURVES[name]
        sec = self.data.get(key)
        if not isinstance(sec, Mapping):
            raise KeyError(f"no {name} curve in these results ({key} absent); curves: "
                           f"{', '.join(self.curves()) or 'none'}")
        out = {col: np.array([np.nan if v is None else v for v in sec[k]], dtype=float)
               for col, k in cols.items() if sec.get(k) is not None}
        n = len(out["theta_deg"])
        return {col: v for col, v in out.items() if v.shape == (n,)}   # per-θ columns only

    def to_dataframe(self, name: str = "calibration") -> pandas.DataFrame:
        """:meth:`curve` as a pandas DataFrame (pandas is optional: an ImportError says so)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - pandas is in requirements.lock
            raise ImportError("Results.to_dataframe needs pandas (pip install pandas); Results.curve(name) gives "
                              "the same columns as numpy arrays") from exc
        return pd.DataFrame(self.curve(name))

    def __repr__(self) -> str:
        parts = [f"{self.kind} dataset {Path(str(self.data.get('dataset', '?'))).name!r}"]
        if (e := self.eccentricity) is not None and (t := self.theta0) is not None:
            parts.append(f"e = {e.value:.3f} ± {e.u:.3f} µm, θ0 = {t.value:.2f} ± {t.u:.2f}°")
        c = self.calibration
        if c is not None and c.error_arcsec:
            err = np.asarray(c.error_arcsec)
            parts.append(f"encoder error P-V {float(np.ptp(err)):.2f}″ at {err.size} angles, "
                         f"U ≤ {max(c.U_arcsec):.2f}″ (k = {c.k:.2f})")
        if (r := self.residual_after or self.residual_before) is not None:
            parts.append(f"residual {float(r['rms_arcsec']):.3f}″ RMS")
        if "identified_effects" in self.data:
            parts.append(f"identified: {', '.join(self.effect_names) or 'none'}")
        return "Results(" + "; ".join(parts) + ")"
