"""Hidden effects: physics the twin simulates but the dataset never declares (issue 7).

A scenario's ``[hidden.<name>]`` tables (schema: ``HIDDEN_EFFECTS`` in ``scenario_schema.py``) change
the twin's TRUTH — the geometry, the disk, the polygon, the instruments' signal chains — while the
manifest and every dataset table are written from the declared (nominal) scenario exactly as
without them. The analysis has to find them from the data alone; ``benchmarks/hidden_suite.py``
scores how well it does (docs/hidden-suite.md).

Every effect is implemented where it physically lives, as its physical cause with its own
parameters and the twin's exact geometry — never with the analysis's fitting formula
(``analysis/effects/*.py``), so that the analysis's library stays an independent description and
a residual can reveal a mismatch (docs/physics.md, "Hidden effects as physical causes"). Where an
effect's parameter is still a coefficient (``sphere_form``'s lobes) it is a coefficient of the
physical object (the sphere's form), not of the analysis's reading model. Some effects keep LEGACY
keys in the analysis's own shapes (``graduation_error`` orders/amplitudes/phases alone,
``interpolation_error`` c1/c2, ``tangential_motion`` x_lobes, ``ac_drift`` rate, ``ac_scale``
gain/quadratic_per_arcsec): ``benchtwin calibrate-twin`` writes a measured effect back in those
shapes, and the analysis's stress tests under ``scenarios/hidden_templates/`` use them; no scenario
of the hidden suite (``scenarios/hidden/``) does (issue 33 item 4, tests/twin/test_hidden_physical.py):

- ``graduation_error``: the hidden part of the disk's LINE-POSITION MAP
  (``instruments/graduation.py``), added to the declared map: k-fold clamping harmonics of the
  lines a_k·cos(k·g − φ_k) (``orders``/``amplitudes``/``phases``; g = nominal value of a line, the
  line lies at body angle g + E(g)), the ruling engine's closed random walk (``ruling_walk_rms``,
  a Brownian bridge, its own stream 202) and an eccentric ruling (``ruling_eccentricity`` at
  ``ruling_eccentricity_azimuth``: lines radial from a point off the edge's centre, a first
  harmonic the heads see and the CCD, which measures the edge, does not). The heads read the
  mean of the lines under their scanning field (65 lines), interpolated between lines, and solve
  g + E(g) = γ as for the declared error (``SimEncoder``). The physical cause of the suite's
  disks is ``form_rms``: the form error of the disk as mounted (and the master wheel's cumulative
  pitch error it was ruled from), a BROADBAND spectrum of orders 2…``form_max_order`` with an
  amplitude envelope ∝ k^(−``form_slope``) and phases drawn from the seed (its own stream 203),
  scaled to rms ``form_rms`` (``form_spectrum``): content at every order, falling with it as the
  self-calibrated division error of Hsieh 2022 fig. 9 does (a dominant 2nd harmonic, smaller
  higher orders; the power law itself is an ASSUMPTION), plus the ruling walk.
- ``optical_radius``: the heads sit at r·(1 + relative) from the axis; the manifest keeps r. The
  exact head geometry then gives the eccentricity and radial-motion errors of the TRUE radius.
- ``ccd_pixel_scale``: the camera's true object-side pixel is pitch·(1 + pixel_relative) (the
  manifest keeps the nominal pitch) and/or the grating's true period at the scale edge is
  period·(1 + grating_period_relative) with the same line count (the disk was ruled on a radius
  (1 + s) larger; the encoder reads angles, so only the CCD sees it). The analysis measures the
  image scale from the grating lines with the datasheet period (Jia eq. 13), so a pixel-pitch error
  cancels in d_ref (what remains is the scale measurement's own noise); a period error does not:
  it scales the measured e by 1/(1 + s) — the library's ``ccd_pixel_scale`` signature.
- ``tangential_motion``: the physical cause is an undeclared waviness of the rotating (inner)
  races, ``race_waviness_top`` / ``race_waviness_bottom`` (lobes {order, amplitude, phase} of the
  rolling path's radial deviation, as the declared ``bearings.waviness_*``), added to the
  bearing's own races and passed through the bench's bearing model (twin/physics.py): a path
  bearing whirls a·(cos(kθ − ψ), sin(kθ − ψ)) per lobe; a ball bearing (``type = "ball"``,
  twin/bearing.py) gets the lobes on its inner race, and the Hertz sums over the balls decide
  which orders move the centre (Wardle's rule). The disk then moves along X as much as along Y:
  Jia eq. 5's ∫δY/r holds 1/k of a lobe, the head on +Y reads −δX/r (exactly, through the posed
  disk); the X probes (``x_probes``) measure the rest. Legacy ``x_lobes``: a·cos(kθ − φ) on both
  rolling paths' x offsets only (no bearing makes such a motion: it is the template's shape).
- ``tilt_abbe``: the spheres sit ``delta_L1`` higher on the shaft than declared (true L1 = L1 + ΔL1,
  L2 unchanged: both spheres move with the ball bar); the model is built with the true L1, the
  manifest keeps the declared one. Probe readings change (the axis tilt is seen at other
  heights); the encoder's α does not.
- ``ac_drift``: the autocollimator's zero follows its own temperature: ``zero_per_kelvin``·
  (T(t) − T(0)), both axes, with T a lumped first-order node (Incropera & DeWitt ch. 5, as
  twin/thermal.py) that warms up after switch-on, ``warmup_rise``·(1 − e^(−t_on/τ)) with
  t_on = t + ``switched_on_before`` and τ = ``warmup_time_constant`` (the light source's and the
  detector electronics' dissipation in the tube), and lags the room's control cycle
  (``room_amplitude``, ``room_period``, phase from the seed: the lag of a sinusoid) with the same
  τ: a drift that slows down as the instrument settles, never rate·t. Legacy ``rate``: rate·t_s.
- ``ac_scale``: the autocollimator's true optics (``instruments/ac_optics.py``): the returned
  beam lands on the detector at f·tan 2v with the TRUE focal length f = f_nom·(1 + δf), on a
  detector tilted by τ, through the objective's Seidel distortion k₁; the firmware inverts with
  f_nom (both axes, before the declared accuracy curve, drift and noise). Keys
  ``focal_length_error``, ``detector_tilt``, ``distortion_k1``, ``focal_length``; the legacy
  ``gain`` / ``quadratic_per_arcsec`` give the δf and τ whose small-angle X reading is
  v·(1 + gain) + q·v²/1″ (the exact law then adds its own higher orders; X axis only, as before):
  a quadratic of 1e-4/″ needs τ ≈ 84° (or δf ≈ −90 %), so the suite states the optics within
  their data sheet (``AC_DATASHEET``: |δf| ≤ 1 %, |τ| ≤ 1°, distortion ≤ 0.1 % at the field edge).
- ``sphere_form``: extra form lobes of a test sphere (body frame, equatorial), added to the
  sphere's declared form; the probes read the lobes turning with the shaft as if it were motion.
- ``torsion_hysteresis``: extra bearing friction torque on the disk section; the static solve
  twists the shaft between disk and polygon by ±T/k_shaft with the approach direction.
- ``polygon_pitch_ignored``: the true polygon differs from its calibration certificate by a
  zero-sum seeded pattern of rms ``rms`` (face angles move, Σβ = 0 kept). The manifest carries
  ``bench.polygon_certificate_arcsec`` = the certificate (the declared polygon's β, Hsieh's
  numbering) whenever this effect is listed — the certificate's VALUES do not depend on the hidden
  pattern. The twin's procedure always runs all N start faces at the first shift, where the
  analysis measures β by closure (Hsieh eqs. 5–6) and ignores the certificate: the pattern is then
  absorbed (expected outcome: nothing to explain). It would only show with a single start face and
  the certificate in use.
- ``interpolation_error``: the sub-division error of the head from its quadrature signals
  (Heydemann 1981, Appl. Opt. 20, 3382): the head's two signals are u = cos φ + p and
  v = r·sin(φ + δ) + q (φ = L·g the grating phase, L lines; offsets ``offset_cos`` p and
  ``offset_sin`` q, amplitude ratio ``amplitude_ratio`` r, quadrature error ``quadrature_error``
  δ); the interpolator takes atan2(v, u) as φ, and the error (atan2(v, u) − φ)/L is computed
  exactly. To first order it is q·cos φ − p·sin φ (the offsets: the FIRST harmonic of the signal
  period) plus ((r − 1)/2)·sin 2φ and (δ/2)·(1 + cos 2φ) (mismatch and quadrature: the SECOND):
  here the physics IS the template's form c1·sin(φ + φ1) + c2·sin(2φ + φ2) (plus second-order
  terms at 2φ, 3φ, 4φ that the exact atan2 keeps). Legacy keys c1/c2 and their phases: that
  form, directly.
- ``thermal_growth`` (OUTSIDE the analysis's library): the disk's hub warms with the bench
  (the structure node of twin/thermal.py: lab air and a share of the motor's heat, through its
  time constants); the hub and the disk expand differently (``cte_mismatch`` = α_hub − α_disk), the
  k clamping screws (``order``, default 7) hold the disk at k points, and the constrained radial
  mismatch Δα·ΔT·r_hub becomes a k-lobed tangential displacement of the lines, a fraction
  ``lobe_coupling`` of it at the graduation: E_T(g, t) = c·Δα·ΔT(t)·(r_hub/r)·cos(k·g − φ),
  ΔT(t) = T_s(t) − T_s(0). A disk-fixed harmonic whose amplitude follows the temperature: neither
  graduation_error (static) nor ac_drift (reference chain) explains it. Without a temperature
  change (no ``[thermal]`` motor rise or lab variation) it is zero.

Seeds: the random hidden quantities have their own streams (the polygon pattern 201, the ruling
walk 202), so hidden effects never change the declared quantities' draws.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from benchtwin.jsonable import to_json
from benchtwin.units import ARCSEC

from .instruments.ac_optics import FOCAL_LENGTH_M, AutocollimatorOptics
from .instruments.graduation import brownian_bridge, dirichlet_factor, eccentric_ruling, harmonics, remove_orders
from .streams import HIDDEN_STREAMS, stream_rng  # the one stream table (HIDDEN_STREAMS: re-exported)

TWO_PI = 2.0 * math.pi

#: the autocollimator's data-sheet ranges the hidden suite keeps to (TRIOPTICS TriAngle US 300-57,
#: MÖLLER-WEDEL ELCOMAT 3000: f = 300 mm; ASSUMPTION for the bounds: the objective's focal length
#: is known to 1 % (refocus, tube temperature), the detector square to its axis within 1°, the
#: objective's distortion ≤ 0.1 % at the ±1000″ field edge, i.e. |k₁|·(tan(2·1000″))² ≤ 1e-3)
AC_DATASHEET = {"focal_length_error": 0.01, "detector_tilt_rad": math.radians(1.0),
                "distortion_k1": 1e-3 / math.tan(2 * 1000 * ARCSEC) ** 2}


def hidden_of(sc: Any) -> dict[str, dict[str, Any]]:
    """The validated ``[hidden]`` tables of a scenario (``{}`` for a plain dict without them)."""
    try:
        h = sc["hidden"]
    except (KeyError, TypeError):
        return {}
    return dict(h or {})


def _lobes(lobes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lobes = list(lobes or [])
    return (np.array([float(l["order"]) for l in lobes]), np.array([float(l["amplitude"]) for l in lobes]),
            np.array([float(l["phase"]) for l in lobes]))


def hidden_for(sc: Any, hidden: "Hidden | None" = None) -> "Hidden":
    """The one place a ``Hidden`` is built: ``hidden`` when given (the bench's, built once per
    bench: ``Bench.hidden``, which every instrument of ``simulate.sim_build`` shares), else the
    scenario's (``Hidden.from_scenario``: an instrument made without its bench's)."""
    return Hidden.from_scenario(sc) if hidden is None else hidden


class Hidden:
    """The hidden effects of one scenario, as the twin's modules consult them. Every accessor
    returns the neutral value (0, 1, empty) for an effect that is not listed."""

    def __init__(self, hidden: Mapping[str, Mapping[str, Any]] | None = None, seed: int = 0):
        self.effects = {k: dict(v) for k, v in (hidden or {}).items()}
        self.seed = int(seed)
        g = self.effects.get("graduation_error")
        if g:
            o, a, p = (list(g.get(k) or []) for k in ("orders", "amplitudes", "phases"))
            if not (len(o) == len(a) == len(p)):
                raise ValueError("hidden.graduation_error: orders, amplitudes and phases must have one "
                                 f"entry each per harmonic (got {len(o)}, {len(a)}, {len(p)})")
            if any(abs(k - round(k)) > 1e-9 or round(k) < 1 for k in o):
                raise ValueError(f"hidden.graduation_error: orders must be positive integers, got {o}")
            self._grad = (np.array([round(k) for k in o], dtype=float), np.array(a, dtype=float),
                          np.array(p, dtype=float))
        else:
            self._grad = (np.zeros(0), np.zeros(0), np.zeros(0))
        self._race_x = _lobes((self.effects.get("tangential_motion") or {}).get("x_lobes"))
        acd = self.effects.get("ac_drift") or {}
        self._ac_room_phase = (float(acd["room_phase"]) if acd.get("room_phase") is not None else float(
            stream_rng(self.seed, "ac_room_phase").uniform(0, TWO_PI)))

    @classmethod
    def from_scenario(cls, sc: Any) -> "Hidden":
        seed = getattr(sc, "seed", None)
        if seed is None:
            try:
                seed = sc["scenario"]["seed"]
            except (KeyError, TypeError):
                seed = 0
        return cls(hidden_of(sc), int(seed))

    def __bool__(self) -> bool:
        return bool(self.effects)

    def _p(self, effect: str, key: str, default: float = 0.0) -> float:
        e = self.effects.get(effect)
        return float(e.get(key, default)) if e else default

    # ------------------------------------------------------------------ geometry
    @property
    def optical_radius_factor(self) -> float:
        return 1.0 + self._p("optical_radius", "relative")

    @property
    def delta_L1_m(self) -> float:
        return self._p("tilt_abbe", "delta_L1")

    @property
    def pixel_scale_extra(self) -> float:
        return self._p("ccd_pixel_scale", "pixel_relative")

    @property
    def grating_scale_factor(self) -> float:
        return 1.0 + self._p("ccd_pixel_scale", "grating_period_relative")

    @property
    def extra_friction_torque_Nm(self) -> float:
        return self._p("torsion_hysteresis", "extra_friction_torque")

    def race_x_offset_m(self, theta_rad: float) -> float:
        """Extra rolling-path x offset of both bearings at shaft angle θ (tangential_motion)."""
        k, a, p = self._race_x
        if not k.size:
            return 0.0
        return float(np.dot(a, np.cos(k * float(theta_rad) - p)))

    def race_waviness_lobes(self, which: str) -> list[dict]:
        """Undeclared waviness lobes of the ``which`` ("top"/"bottom") bearing's rotating race
        (tangential_motion), in the declared ``bearings.waviness_*`` form: the bearing model adds
        them to its own race (twin/physics.py)."""
        e = self.effects.get("tangential_motion") or {}
        return [{"order": int(l["order"]), "amplitude": float(l["amplitude"]), "phase": float(l["phase"])}
                for l in (e.get(f"race_waviness_{which}") or [])]

    def sphere_form_lobes(self, which: str) -> list[dict]:
        e = self.effects.get("sphere_form") or {}
        return [{"order": int(l["order"]), "amplitude": float(l["amplitude"]), "phase": float(l["phase"])}
                for l in (e.get(which) or [])]

    def polygon_pitch_pattern_rad(self, n_faces: int) -> np.ndarray:
        """Zero-sum pattern added to the polygon's pitch deviations (physics numbering)."""
        rms = self._p("polygon_pitch_ignored", "rms")
        if rms == 0.0:
            return np.zeros(n_faces)
        r = stream_rng(self.seed, "polygon_pitch_pattern")
        x = r.normal(0.0, 1.0, n_faces)
        x -= x.mean()
        return x * (rms / math.sqrt(np.mean(x**2)))

    @property
    def writes_certificate(self) -> bool:
        return "polygon_pitch_ignored" in self.effects

    # ------------------------------------------------------------------ the disk / heads
    @property
    def has_graduation(self) -> bool:
        e = self.effects.get("graduation_error") or {}
        static = bool(self._grad[0].size) or any(float(e.get(k, 0.0)) for k in ("ruling_walk_rms", "ruling_eccentricity",
                                                                                 "form_rms"))
        return static or self.thermal_lobe_rad_per_K(1.0) != 0.0

    def graduation_line_error_rad(self, n_lines: int, radius_m: float) -> np.ndarray | None:
        """The hidden part of the disk's line-position map (rad per line, ``graduation.py``): the
        ruling engine's closed random walk (``ruling_walk_rms``, rms of the line positions, its own
        seeded stream), the clamping harmonics (``orders``/``amplitudes``/``phases``) and an
        eccentric ruling (``ruling_eccentricity`` at ``ruling_eccentricity_azimuth``, seen at the
        heads' radius). None when the effect is not listed."""
        e = self.effects.get("graduation_error")
        if not e:
            return None
        n = int(n_lines)
        k, a, p = self._grad
        out = harmonics(n, k, a, p)
        form_rms = float(e.get("form_rms", 0.0))
        if form_rms:
            ko, ao, po = self.form_spectrum()
            out = out + harmonics(n, ko, ao, po)
        walk_rms = float(e.get("ruling_walk_rms", 0.0))
        if walk_rms:
            r = stream_rng(self.seed, "graduation_walk")
            w = remove_orders(brownian_bridge(n, r), (0, 1))
            out = out + w * (walk_rms / math.sqrt(np.mean(w**2)))
        ecc = float(e.get("ruling_eccentricity", 0.0))
        if ecc:
            out = out + eccentric_ruling(n, ecc, float(e.get("ruling_eccentricity_azimuth", 0.0)), radius_m)
        return out

    def form_spectrum(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(orders, amplitudes rad, phases rad) of the disk's mounted form error (graduation_error
        ``form_rms``): orders 2…``form_max_order``, amplitudes ∝ k^(−``form_slope``) scaled so that
        the line positions' rms is ``form_rms`` (a sum of cosines has rms √(Σa²/2)), phases uniform
        from the seed's stream 203. Empty when not stated."""
        e = self.effects.get("graduation_error") or {}
        rms = float(e.get("form_rms", 0.0))
        if not rms:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        k = np.arange(2, int(e.get("form_max_order", 200)) + 1, dtype=float)
        a = k ** (-float(e.get("form_slope", 1.5)))
        a *= rms / math.sqrt(0.5 * float(np.sum(a * a)))
        r = stream_rng(self.seed, "graduation_form")
        return k, a, r.uniform(0.0, TWO_PI, k.size)

    def thermal_lobe_rad_per_K(self, radius_m: float) -> float:
        """Amplitude of the clamp's k-lobed line displacement per kelvin of hub temperature rise,
        at the heads' radius: c·Δα·r_hub / r (``thermal_growth``; 0 when not listed)."""
        e = self.effects.get("thermal_growth")
        if not e:
            return 0.0
        return (float(e.get("lobe_coupling", 0.5)) * float(e.get("cte_mismatch", 15e-6))
                * float(e.get("hub_radius", 10e-3)) / float(radius_m))

    def thermal_graduation_error_rad(self, g, t_s: float, thermal, radius_m: float, n_lines: int,
                                     window_lines: int) -> np.ndarray:
        """The clamp's thermal k-lobed distortion of the graduation at t (rad), as the heads read it:
        amplitude per K × the hub's temperature rise ΔT(t) = T_s(t) − T_s(0) of the thermal model's
        structure node (twin/thermal.py), times the head field's Dirichlet factor."""
        g = np.asarray(g, dtype=float)
        a_K = self.thermal_lobe_rad_per_K(radius_m)
        if not a_K or thermal is None:
            return np.zeros_like(g)
        dT = thermal.structure_rise_K(t_s)
        if dT == 0.0:
            return np.zeros_like(g)
        e = self.effects["thermal_growth"]
        k = int(e.get("order", 7))
        A = a_K * dT * dirichlet_factor(k, n_lines, window_lines)
        return A * np.cos(k * g - float(e.get("phase", 0.0)))

    def interpolation_error_rad(self, signal_phase, n_lines: int) -> np.ndarray:
        """Extra sub-division error (rad of the shaft) at grating signal phase φ = L·g: Heydemann's
        error of the quadrature signals, (atan2(v, u) − φ)/L exactly, wrapped to (−π, π]/L, plus
        the legacy c1/c2 terms."""
        x = np.asarray(signal_phase, dtype=float)
        out = heydemann_phase_error_rad(x, self._p("interpolation_error", "offset_cos"),
                                        self._p("interpolation_error", "offset_sin"),
                                        self._p("interpolation_error", "amplitude_ratio", 1.0),
                                        self._p("interpolation_error", "quadrature_error")) / float(n_lines)
        for m in (1, 2):
            c = self._p("interpolation_error", f"c{m}")
            if c:
                out = out + c * np.sin(m * x + self._p("interpolation_error", f"c{m}_phase"))
        return out

    # ------------------------------------------------------------------ autocollimator
    def ac_optics(self) -> AutocollimatorOptics | None:
        """The autocollimator's true optics (``ac_scale``), None when the effect is not listed."""
        e = self.effects.get("ac_scale")
        if not e:
            return None
        f_nom = float(e.get("focal_length", FOCAL_LENGTH_M))
        k1 = float(e.get("distortion_k1", 0.0))
        g, q = float(e.get("gain", 0.0)), float(e.get("quadratic_per_arcsec", 0.0))
        df, tau = float(e.get("focal_length_error", 0.0)), float(e.get("detector_tilt", 0.0))
        if (g or q) and (df or tau):
            raise ValueError("hidden.ac_scale: give the optics (focal_length_error, detector_tilt) or the "
                             "legacy coefficients (gain, quadratic_per_arcsec), not both")
        if g or q:
            return AutocollimatorOptics.from_coefficients(g, q, focal_length_m=f_nom, distortion_k1=k1)
        return AutocollimatorOptics(focal_length_error=df, detector_tilt_rad=tau, distortion_k1=k1, focal_length_m=f_nom)

    def ac_temperature_rise_K(self, t_s: float) -> float:
        """The autocollimator's own temperature at t minus at t = 0 (K, ``ac_drift``): a lumped node
        with time constant τ warming up by ``warmup_rise``·(1 − e^(−t_on/τ)), t_on = t +
        ``switched_on_before``, and lagging the room's cycle ±``room_amplitude`` of period
        ``room_period`` (periodic steady state of τ·y' + y = A·sin(ωt + φ)): closed form."""
        t = float(t_s)
        tau = self._p("ac_drift", "warmup_time_constant", 1800.0)
        t_on0 = self._p("ac_drift", "switched_on_before")
        rise = self._p("ac_drift", "warmup_rise")
        A = self._p("ac_drift", "room_amplitude")
        w = TWO_PI / self._p("ac_drift", "room_period", 1200.0)
        warm = rise * (math.exp(-t_on0 / tau) - math.exp(-(t_on0 + t) / tau)) if rise else 0.0
        if not A:
            return warm
        g, lag = A / math.sqrt(1.0 + (w * tau) ** 2), math.atan(w * tau)
        return warm + g * (math.sin(w * t + self._ac_room_phase - lag) - math.sin(self._ac_room_phase - lag))

    def ac_zero_drift_rad(self, t_s: float) -> float:
        """Extra autocollimator zero drift at t (``ac_drift``), both axes: ``zero_per_kelvin`` times
        the instrument's temperature change (``ac_temperature_rise_K``), plus the legacy rate·t."""
        out = self._p("ac_drift", "rate") * float(t_s)
        s = self._p("ac_drift", "zero_per_kelvin")
        return out + s * self.ac_temperature_rise_K(t_s) if s else out

    # ------------------------------------------------------------------ truth
    def truth(self, n_faces: int | None = None, thermal: Any = None, radius_m: float | None = None,
              t_end_s: float | None = None) -> dict:
        out: dict[str, Any] = {"effects": {k: _json(v) for k, v in self.effects.items()},
                               "note": "SI values; see twin/hidden.py for each effect's physics"}
        if "thermal_growth" in self.effects and radius_m:
            tg: dict[str, Any] = {"amplitude_rad_per_K": self.thermal_lobe_rad_per_K(radius_m),
                                  "temperature": "structure node of twin/thermal.py, rise since t = 0"}
            if thermal is not None and t_end_s is not None:
                tg["structure_rise_K_at_end"] = thermal.structure_rise_K(t_end_s)
                tg["t_end_s"] = float(t_end_s)
            out["thermal_growth"] = tg
        optics = self.ac_optics()
        if optics is not None:
            out["autocollimator_optics"] = optics.truth()
        if n_faces and "polygon_pitch_ignored" in self.effects:
            out["polygon_pitch_pattern_physics_arcsec"] = (self.polygon_pitch_pattern_rad(n_faces) / ARCSEC).tolist()
        return out


_json = to_json  # the one numpy -> JSON conversion (benchtwin/jsonable.py)


def heydemann_phase_error_rad(phase, offset_cos: float = 0.0, offset_sin: float = 0.0,
                              amplitude_ratio: float = 1.0, quadrature_error_rad: float = 0.0) -> np.ndarray:
    """Interpolation (phase) error of imperfect quadrature signals, rad of signal phase (Heydemann
    1981, Appl. Opt. 20, 3382): u = cos φ + p, v = r·sin(φ + δ) + q; the interpolator's
    atan2(v, u) minus φ, wrapped to (−π, π]. Exact; to first order q·cos φ − p·sin φ
    + ((r − 1)/2)·sin 2φ + (δ/2)·(1 + cos 2φ)."""
    phi = np.asarray(phase, dtype=float)
    if offset_cos == 0.0 and offset_sin == 0.0 and amplitude_ratio == 1.0 and quadrature_error_rad == 0.0:
        return np.zeros_like(phi)
    u = np.cos(phi) + offset_cos
    v = amplitude_ratio * np.sin(phi + quadrature_error_rad) + offset_sin
    return np.angle(np.exp(1j * (np.arctan2(v, u) - phi)))

class TrueScenario:
    """A read-only view of a scenario with some ``[bench]`` values replaced by their TRUE values
    (for building the physical model: e.g. the spheres at the true L1). Everything else is the
    scenario's."""

    def __init__(self, sc: Any, bench_overrides: Mapping[str, Any]):
        self._sc = sc
        self._bench = {**dict(sc["bench"]), **bench_overrides}

    def __getitem__(self, key: str) -> Any:
        return self._bench if key == "bench" else self._sc[key]

    def get(self, key: str, default: Any = None) -> Any:
        try:
            return self[key]
        except KeyError:
            return default

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sc, name)


__all__ = ["Hidden", "hidden_for", "hidden_of", "TrueScenario", "HIDDEN_STREAMS", "AC_DATASHEET", "heydemann_phase_error_rad"]
