"""GUM uncertainty budgets on GTC, a GUM-S1 Monte Carlo check, E_n numbers and the range method.

References: JCGM 100:2008 (GUM) — eq. 10 (law of propagation, uncorrelated inputs), G.4.1
(Welch–Satterthwaite, ν_eff truncated to the next lower integer), G.4.2 (ν ≈ ½·(Δu/u)⁻², so a 10 %
relative uncertainty of u gives ν = 50), G.3 (k = t_p(ν)); JCGM 101:2008 (GUM Supplement 1) — 6.4.3
(rectangular), 6.4.9 (scaled and shifted t for type A), 7.7 (probabilistically symmetric and shortest
coverage intervals), 8 (validation of the GUM uncertainty framework against Monte Carlo).

Hsieh, Watanabe, Hsu, Appl. Sci. 12 (2022) 5008, sec. 3.3: eq. 10 (budget of α), eq. 11 (Estler's
sensitivity ∂α/∂β = 1/n − 8/(9n²), Estler, J. Res. NIST 103 (1998) 141), eq. 12 (U_shift), Table 3,
eq. 13 (E_n). Jia et al., Appl. Sci. 9 (2019) 3415: the range method u = R/d_n (d_3 = 1.69).

The budget (:class:`UncertaintyBudget`) builds one GTC ``ureal`` per contribution (value 0, its
standard uncertainty, its dof, its name as label) and the measurand as Σ c_i·X_i; GTC supplies u_c and
the Welch–Satterthwaite ν_eff; k = Student's quantile ``t_ppf((1 + p)/2, ν)`` (analysis/distributions.py) with ν truncated to an integer
(GUM G.4.1; ``truncate_dof=False`` uses the real ν).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import cast

import GTC
import numpy as np

from .distributions import norm_ppf, t_ppf

__all__ = [
    "Contribution",
    "UncertaintyBudget",
    "coverage_factor",
    "dof_from_relative_uncertainty",
    "estler_sensitivity",
    "en_number",
    "D_N",
    "range_uncertainty",
    "MCResult",
    "draw_samples",
    "monte_carlo",
    "coverage_interval_shortest",
    "coverage_interval_symmetric",
    "validate_gum_with_mc",
    "shift_angle_budget",
    "ShiftAngleBudgetInputs",
    "TypeBInputs",
    "HSIEH2022_TYPE_B",
    "hsieh2022_table3_budget",
]

INF = math.inf


def coverage_factor(dof: float, p: float = 0.95, *, truncate: bool = True) -> float:
    """k = t_{(1+p)/2}(ν) (GUM G.3); ν truncated to the next lower integer first (GUM G.4.1); ν = ∞ → normal."""
    if not 0 < p < 1:
        raise ValueError(f"coverage probability p must be in (0, 1), got {p}")
    if dof is None or not math.isfinite(dof):
        return float(norm_ppf(0.5 + p / 2))
    nu = math.floor(dof) if truncate else float(dof)
    if nu < 1:
        raise ValueError(f"degrees of freedom must be >= 1, got {dof}")
    return float(t_ppf(0.5 + p / 2, nu))


def dof_from_relative_uncertainty(relative: float) -> float:
    """GUM eq. G.3: ν ≈ ½·(Δu/u)⁻²; 10 % → 50, 0 % → ∞."""
    if relative < 0:
        raise ValueError("relative uncertainty must be >= 0")
    return INF if relative == 0 else float(f"{0.5 / relative**2:.12g}")  # 10 % → exactly 50


def estler_sensitivity(n_faces: int) -> float:
    """Hsieh eq. 11 (after Estler 1998): ∂α/∂β = 1/n − 8/(9n²); n = 24 → 0.0401."""
    n = float(n_faces)
    return 1.0 / n - 8.0 / (9.0 * n * n)


def en_number(x1: np.ndarray | float, U1: np.ndarray | float, x2: np.ndarray | float, U2: np.ndarray | float
              ) -> np.ndarray | float:
    """The standard E_n = |x1 − x2| / √(U1² + U2²) (ISO/IEC 17043, expanded uncertainties U).

    Note: Hsieh 2022 eq. 13 prints √(U_shift² − U_self²) (a minus sign); that is not the E_n number
    (it is undefined for U_self > U_shift and overstates E_n otherwise). This function uses the plus sign.
    """
    x1, U1, x2, U2 = (np.asarray(v, dtype=float) for v in (x1, U1, x2, U2))
    out = np.abs(x1 - x2) / np.sqrt(U1**2 + U2**2)
    return float(out) if out.ndim == 0 else out


#: d_n of the range method (the mean range of n normal samples in units of σ), n = 2…25: the one
#: table, in analysis.radial_motion (it was copied here for n ≤ 10).
from benchtwin.analysis.radial_motion import D_N  # noqa: E402



def range_uncertainty(values_or_range: Sequence[float] | np.ndarray | float, n: int | None = None, *,
                      d_n: float | None = None) -> float:
    """Standard deviation from the range: s = R/d_n (GUM 4.2.3 note; Jia 2019 uses d_3 = 1.69).

    Pass the readings (n taken from them) or a range R with ``n``. ``d_n`` overrides the table
    (e.g. ``d_n=1.69`` to follow Jia exactly).
    """
    v = np.asarray(values_or_range, dtype=float)
    if v.ndim == 0:
        if n is None:
            raise ValueError("give n with a range value")
        R = float(v)
    else:
        n = v.size if n is None else n
        R = float(v.max() - v.min())
    if d_n is None:
        if n not in D_N:
            raise ValueError(f"d_n tabulated for n = 2…25 only, got n = {n}")
        d_n = D_N[n]
    return R / d_n


# --------------------------------------------------------------------------- the budget


@dataclass
class Contribution:
    """One input quantity X_i: standard uncertainty ``u``, sensitivity c_i = ∂y/∂X_i, dof ν_i.

    ``group``: contributions that together form an intermediate quantity (e.g. Hsieh's "measured value
    uncertainty ε"); ``distribution``: ``normal``, ``rectangular`` or ``t`` (for Monte Carlo only).
    """

    name: str
    u: float
    sensitivity: float = 1.0
    dof: float = INF
    group: str | None = None
    distribution: str = "normal"
    note: str = ""

    @property
    def contribution(self) -> float:
        return abs(self.sensitivity) * self.u


@dataclass
class UncertaintyBudget:
    """A GUM budget of a linear(ised) measurand y = Σ c_i·X_i, computed with GTC.

    ``u_c``, ``nu_eff`` (Welch–Satterthwaite, from GTC), ``k`` (t-distribution), ``U`` = k·u_c;
    ``group_u(name)``/``group_dof(name)`` for an intermediate quantity; ``table()`` rows and ``str()``
    a table like Hsieh 2022 Table 3; ``monte_carlo()`` propagates the input distributions (GUM-S1).
    """

    title: str = "uncertainty budget"
    measurand: str = "α"
    unit: str = '"'
    p: float = 0.95
    truncate_dof: bool = True
    contributions: list[Contribution] = field(default_factory=list)

    # ---- building
    def add(self, name: str, u: float, sensitivity: float = 1.0, dof: float = INF, *, group: str | None = None,
            distribution: str = "normal", note: str = "") -> Contribution:
        if not (math.isfinite(u) and u >= 0):
            raise ValueError(f"{name}: standard uncertainty must be finite and >= 0, got {u}")
        if not (dof is None or dof > 0):
            raise ValueError(f"{name}: dof must be > 0, got {dof}")
        if distribution not in ("normal", "rectangular", "t"):
            raise ValueError(f"{name}: distribution must be normal/rectangular/t, got {distribution!r}")
        if any(c.name == name for c in self.contributions):
            raise ValueError(f"duplicated contribution name {name!r}")
        c = Contribution(name, float(u), float(sensitivity), INF if dof is None else float(dof), group, distribution,
                         note)
        self.contributions.append(c)
        return c

    def add_type_a(self, name: str, sd: float, n: int, sensitivity: float = 1.0, **kw) -> Contribution:
        """Type A: u = s/√n, ν = n − 1 (a mean of n readings; the S1 distribution is the scaled t)."""
        kw.setdefault("distribution", "t")
        return self.add(name, sd / math.sqrt(n), sensitivity, n - 1, **kw)

    def add_rectangular(self, name: str, half_width: float, sensitivity: float = 1.0, dof: float = INF, **kw
                        ) -> Contribution:
        """Type B, rectangular of half-width a: u = a/√3 (a resolution r has a = r/2: u = r/(2√3))."""
        return self.add(name, half_width / math.sqrt(3.0), sensitivity, dof, distribution="rectangular", **kw)

    # ---- GTC
    def _ureals(self) -> list:
        return [GTC.ureal(0.0, c.u, c.dof, label=c.name) for c in self.contributions]

    def _combine(self, members: Sequence[int]):
        xs = self._ureals()
        y = GTC.ureal(0.0, 0.0)
        for i in members:
            y = y + self.contributions[i].sensitivity * xs[i]
        return y

    def gtc_result(self, value: float = 0.0):
        """The measurand as a GTC ``ureal`` (value + Σ c_i·X_i)."""
        return value + self._combine(range(len(self.contributions)))

    @property
    def u_c(self) -> float:
        return float(math.sqrt(sum(c.contribution**2 for c in self.contributions)))

    @property
    def nu_eff(self) -> float:
        if self.u_c == 0:
            return INF
        return float(self._combine(range(len(self.contributions))).df)

    @property
    def k(self) -> float:
        return coverage_factor(self.nu_eff, self.p, truncate=self.truncate_dof)

    @property
    def U(self) -> float:
        return self.k * self.u_c

    def groups(self) -> list[str]:
        out: list[str] = []
        for c in self.contributions:
            if c.group is not None and c.group not in out:
                out.append(c.group)
        return out

    def _members(self, group: str) -> list[int]:
        idx = [i for i, c in enumerate(self.contributions) if c.group == group]
        if not idx:
            raise KeyError(f"no contributions in group {group!r}")
        return idx

    def group_u(self, group: str) -> float:
        """u of the intermediate quantity formed by the group (root sum square of |c|·u)."""
        return float(math.sqrt(sum(self.contributions[i].contribution ** 2 for i in self._members(group))))

    def group_dof(self, group: str) -> float:
        """Welch–Satterthwaite ν of the group (GTC)."""
        y = self._combine(self._members(group))
        return INF if y.u == 0 else float(y.df)

    # ---- reporting
    def table(self) -> list[dict[str, object]]:
        """Rows (dicts) in Table-3 order: each group (``kind='group'``) followed by its members
        (``kind='member'``), then ungrouped contributions, then ``kind='combined'`` with u_c, ν_eff, k, U."""
        rows: list[dict[str, object]] = []
        done: set[str] = set()

        def row(c: Contribution, kind: str) -> dict[str, object]:
            return {"kind": kind, "name": c.name, "u": c.u, "sensitivity": c.sensitivity,
                    "contribution": c.contribution, "dof": c.dof, "group": c.group, "distribution": c.distribution}

        for c in self.contributions:
            if c.group is None:
                rows.append(row(c, "contribution"))
            elif c.group not in done:
                done.add(c.group)
                gu = self.group_u(c.group)
                rows.append({"kind": "group", "name": c.group, "u": gu, "sensitivity": 1.0, "contribution": gu,
                             "dof": self.group_dof(c.group), "group": None, "distribution": ""})
                rows += [row(self.contributions[i], "member") for i in self._members(c.group)]
        rows.append({"kind": "combined", "name": "combined standard uncertainty", "u": self.u_c, "sensitivity": None,
                     "contribution": self.u_c, "dof": self.nu_eff, "k": self.k, "U": self.U, "p": self.p,
                     "group": None, "distribution": ""})
        return rows

    def __str__(self) -> str:
        def dof_s(v: float) -> str:
            return "∞" if not math.isfinite(v) else f"{v:.0f}" if abs(v - round(v)) < 1e-9 else f"{v:.1f}"

        u = self.unit
        head = f"{'Standard uncertainty':<56} {'u(Xi)':>9} {'∂' + self.measurand + '/∂Xi':>9} {'|c|u(Xi)':>9} {'dof':>6}"
        lines = [self.title, head, "-" * len(head)]
        for r in self.table():
            if r["kind"] == "combined":
                continue
            name = ("  " if r["kind"] == "member" else "") + str(r["name"])
            lines.append(f"{name[:56]:<56} {r['u']:>8.4f}{u} {r['sensitivity']:>9.4g} {r['contribution']:>8.4f}{u} "
                         f"{dof_s(float(cast(float, r['dof']))):>6}")
        lines.append("-" * len(head))
        nu = self.nu_eff
        nu_s = dof_s(math.floor(nu) if (self.truncate_dof and math.isfinite(nu)) else nu)
        lines.append(f"Combined standard uncertainty (u): {self.u_c:.4f}{u}, effective degrees of freedom (ν_eff): "
                     f"{nu_s} (WS {nu:.2f}), expanded uncertainty ({self.p:.0%} level): {self.U:.4f}{u} (k = {self.k:.2f})")
        return "\n".join(lines)

    # ---- Monte Carlo (GUM-S1)
    def monte_carlo(self, n: int = 200_000, *, rng: np.random.Generator | int = 0,
                    func: Callable[..., np.ndarray] | None = None) -> "MCResult":
        """Draw every input from its distribution (mean 0, std u; ``t``: scaled-shifted t with scale u and
        ν dof, as GUM-S1 6.4.9) and propagate through ``func(**{name: samples})`` (default Σ c_i·X_i)."""
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        samples = {c.name: draw_samples(c.distribution, 0.0, c.u, n, g, dof=c.dof) for c in self.contributions}
        if func is None:
            def func(**kw):
                return sum(c.sensitivity * kw[c.name] for c in self.contributions)
        return monte_carlo(func, samples, p=self.p)


# --------------------------------------------------------------------------- Monte Carlo


@dataclass(frozen=True)
class MCResult:
    """GUM-S1 summary: ``mean``, ``std``, ``shortest`` and ``symmetric`` p-coverage intervals, M samples."""

    mean: float
    std: float
    shortest: tuple[float, float]
    symmetric: tuple[float, float]
    n: int
    p: float


def draw_samples(distribution: str, x: float, u: float, n: int, rng: np.random.Generator, *, dof: float = INF
                 ) -> np.ndarray:
    """n samples of an input with estimate x and standard uncertainty u: ``normal`` N(x, u²),
    ``rectangular`` (half-width u√3), ``t`` x + u·t_ν (GUM-S1 6.4.9; std u·√(ν/(ν−2)) > u; normal if ν = ∞)."""
    if distribution == "normal" or (distribution == "t" and not math.isfinite(dof)):
        return x + u * rng.standard_normal(n)
    if distribution == "rectangular":
        a = u * math.sqrt(3.0)
        return rng.uniform(x - a, x + a, n)
    if distribution == "t":
        return x + u * rng.standard_t(dof, n)
    raise ValueError(f"unknown distribution {distribution!r}")


def coverage_interval_symmetric(y: np.ndarray, p: float = 0.95) -> tuple[float, float]:
    """Probabilistically symmetric p-coverage interval: the (1−p)/2 and (1+p)/2 quantiles (GUM-S1 7.7.1)."""
    ys = np.sort(np.asarray(y, dtype=float).ravel())
    M = ys.size
    q = int(round(p * M))
    r = int(round((M - q) / 2))
    r = min(max(r, 0), M - q)
    return float(ys[r]), float(ys[min(r + q, M - 1)])


def coverage_interval_shortest(y: np.ndarray, p: float = 0.95) -> tuple[float, float]:
    """Shortest p-coverage interval (GUM-S1 7.7.2): min over r of y_(r+q) − y_(r), q = round(pM)."""
    ys = np.sort(np.asarray(y, dtype=float).ravel())
    M = ys.size
    q = min(int(round(p * M)), M - 1)
    w = ys[q:] - ys[: M - q]
    r = int(np.argmin(w))
    return float(ys[r]), float(ys[r + q])


def monte_carlo(func: Callable[..., np.ndarray], samples: Mapping[str, np.ndarray], *, p: float = 0.95) -> MCResult:
    """GUM-S1 propagation: y = func(**samples) evaluated on arrays of M input draws."""
    y = np.asarray(func(**samples), dtype=float).ravel()
    if not np.all(np.isfinite(y)):
        raise ValueError("the model returned non-finite values for some samples")
    return MCResult(float(y.mean()), float(y.std(ddof=1)), coverage_interval_shortest(y, p),
                    coverage_interval_symmetric(y, p), int(y.size), p)


def validate_gum_with_mc(y: float, U: float, mc: MCResult, u_c: float, *, ndig: int = 2, interval: str = "shortest"
                         ) -> dict[str, float | bool]:
    """GUM-S1 8.2: the GUM interval y ± U is validated if |y − U − low| and |y + U − high| ≤ δ, with δ the
    numerical tolerance of u_c at ``ndig`` significant digits (½·10^ℓ, u_c = c·10^ℓ, c of ndig digits)."""
    ell = math.floor(math.log10(abs(u_c))) - (ndig - 1)
    delta = 0.5 * 10.0**ell
    lo, hi = mc.shortest if interval == "shortest" else mc.symmetric
    d_low, d_high = abs(y - U - lo), abs(y + U - hi)
    return {"d_low": d_low, "d_high": d_high, "delta": delta, "ok": bool(d_low <= delta and d_high <= delta)}


# --------------------------------------------------------------------------- Hsieh 2022 sec. 3.3


@dataclass(frozen=True)
class TypeBInputs:
    """The declared type-B inputs of the shift-angle budget (Hsieh 2022 sec. 3.3 items (2)-(5), (8)),
    arcsec: autocollimator resolution r (→ r/(2√3)), traceability U with its k (→ U/k, ν = ∞), angle
    error half-width a (→ a/√3), encoder resolution r (→ r/(2√3)), polygon setup misalignment m
    (→ m/(2√3)); ``type_b_relative``: the relative uncertainty of the type-B u's (10 % → ν = 50,
    GUM G.4.2)."""

    ac_resolution_arcsec: float = 0.0
    ac_traceability_U_arcsec: float = 0.0
    ac_traceability_k: float = 2.0
    ac_error_half_width_arcsec: float = 0.0
    encoder_resolution_arcsec: float = 0.0
    setup_misalignment_arcsec: float = 0.0
    type_b_relative: float = 0.10


#: Hsieh 2022 sec. 3.3's declared inputs: ELCOMAT 3000 resolution 0.001″, traceability U = 0.01″
#: (k = 2), maximum error 0.05″, setup misalignment 0.05″; the encoder resolution comes from the
#: bench (0 if unknown).
HSIEH2022_TYPE_B = TypeBInputs(ac_resolution_arcsec=0.001, ac_traceability_U_arcsec=0.01, ac_traceability_k=2.0,
                               ac_error_half_width_arcsec=0.05, encoder_resolution_arcsec=0.0,
                               setup_misalignment_arcsec=0.05, type_b_relative=0.10)


@dataclass(frozen=True)
class ShiftAngleBudgetInputs:
    """What the data give the shift-angle budget (arcsec): (1) the repeatability of α with its dof,
    (6) the residual setup-error calculation d (eq. 7 vs curve fit), (7) the repeatability of β with
    its dof and sensitivity (None: eq. 11's 1/n − 8/(9n²)), and (9) the direction difference Δ with
    its dof (None: no row; dof None: as type B)."""

    u_repeat_alpha_arcsec: float
    dof_repeat_alpha: float
    n_faces: int
    u_repeat_beta_arcsec: float = 0.0
    dof_repeat_beta: float = INF
    setup_residual_arcsec: float = 0.0
    sensitivity_beta: float | None = None
    direction_difference_arcsec: float | None = None
    dof_direction: float | None = None


def shift_angle_budget(inputs: ShiftAngleBudgetInputs, type_b: TypeBInputs | None = None, *,
                       title: str = "Combined uncertainty for shift-angle method") -> UncertaintyBudget:
    """The budget of α for the shift-angle method, Hsieh 2022 sec. 3.3 items (1)-(8), eq. 10, Table 3.

    Group "measured value uncertainty, ε" (sensitivity 1): (1) repeatability ``u_repeat_alpha_arcsec``
    (type A, its dof); (2) AC resolution r → r/(2√3); (3) AC traceability U/k (ν = ∞: relative
    uncertainty 0 %, as the text says; the Table prints 50, which changes nothing visible);
    (4) AC angle error, rectangular half-width a → a/√3; (5) encoder resolution r → r/(2√3);
    (6) residual setup-error calculation d (eq. 7 vs curve fit) → d/(2√3). Then (7) repeatability of β
    with sensitivity 1/n − 8/(9n²) (eq. 11) and (8) the polygon setup error (misalignment m → m/(2√3)).
    Type-B dofs from ``type_b.type_b_relative`` (10 % → 50, GUM G.4.2). Inputs in arcsec; ``type_b``
    None: all type-B inputs 0 (:class:`TypeBInputs`).

    ``inputs.sensitivity_beta`` replaces eq. 11 where the estimator's own sensitivity is known (the data
    pipeline takes it from the Jacobian of α with respect to β). ``inputs.direction_difference_arcsec``:
    the part of α(forward) − α(backward) that the repeatability does not explain (hysteresis that
    depends on θ); the direction-averaged α lies midway, so a reading in one direction is off by up to
    half of it: (9) rectangular of half-width Δ/2, u = Δ/(2√3), ν from ``dof_direction`` (default as
    type B). Omitted (not even a zero row) when None.
    """
    d, tb = inputs, (type_b if type_b is not None else TypeBInputs())
    nu_b = dof_from_relative_uncertainty(tb.type_b_relative)
    rt3 = math.sqrt(3.0)
    g = "measured value uncertainty, ε"
    b = UncertaintyBudget(title=title)
    b.add("Repeatability of angle error measurement", d.u_repeat_alpha_arcsec, 1.0, d.dof_repeat_alpha, group=g,
          distribution="t")
    b.add("Resolution of the autocollimator", tb.ac_resolution_arcsec / (2 * rt3), 1.0, nu_b, group=g,
          distribution="rectangular")
    b.add("Traceability of the autocollimator", tb.ac_traceability_U_arcsec / tb.ac_traceability_k, 1.0, INF,
          group=g)
    b.add("Angle error of autocollimator", tb.ac_error_half_width_arcsec / rt3, 1.0, nu_b, group=g,
          distribution="rectangular")
    b.add("Resolution of the rotary encoder", tb.encoder_resolution_arcsec / (2 * rt3), 1.0, nu_b, group=g,
          distribution="rectangular")
    b.add("Residual setup error calculation", d.setup_residual_arcsec / (2 * rt3), 1.0, nu_b, group=g,
          distribution="rectangular")
    c_beta = estler_sensitivity(d.n_faces) if d.sensitivity_beta is None else float(d.sensitivity_beta)
    b.add("Repeatability of the pitch angle deviation measurement", d.u_repeat_beta_arcsec, c_beta,
          d.dof_repeat_beta, distribution="t")
    b.add("setup error uncertainty", tb.setup_misalignment_arcsec / (2 * rt3), 1.0, nu_b, distribution="rectangular")
    if d.direction_difference_arcsec is not None:
        b.add("Direction difference (forward − backward)", abs(float(d.direction_difference_arcsec)) / (2 * rt3), 1.0,
              nu_b if d.dof_direction is None else d.dof_direction, distribution="rectangular")
    return b


def hsieh2022_table3_budget(*, traceability_dof: float = INF) -> UncertaintyBudget:
    """Hsieh 2022 Table 3 with the standard uncertainties as printed in the paper (arcsec).

    Reproduces u(ε) = 0.0676″ (ν_eff 12.8 → 12), u_c = 0.069″ ≈ 0.07″, ν_eff = 13.9 → 13 (13.1 if ε is
    entered as one input with ν = 12, → 13 as well), k = t_0.975(13) = 2.16 and U = 0.149″ ≈ 0.15″: the
    paper's eq. 12 and Table 3 (k = 2.16). The text's "k = 2.31" is t_0.975(8) and matches none of the
    paper's ν; it is not reproduced. Dofs: repeatabilities 5, type B 50, traceability ∞ (text) — with the
    Table's 50 every printed number is the same (``traceability_dof=50``).

    The printed u values are used as they stand although some do not follow from the stated inputs:
    0.04″/(2√3) = 0.0115″ (printed 0.0101″), "maximum error 0.05″" but 0.07″/√3 = 0.0404″ is used,
    0.0001″/(2√3) = 0.00003″ (printed 0.0001″). :func:`shift_angle_budget` computes from the inputs.
    """
    g = "measured value uncertainty, ε"
    b = UncertaintyBudget(title="Table 3. Combined uncertainty for shift-angle method (Hsieh 2022)")
    b.add("Repeatability of angle error measurement", 0.0531, 1.0, 5, group=g, distribution="t")
    b.add("Resolution of the autocollimator", 0.0003, 1.0, 50, group=g, distribution="rectangular")
    b.add("Traceability of the autocollimator", 0.0050, 1.0, traceability_dof, group=g)
    b.add("Angle error of autocollimator", 0.0404, 1.0, 50, group=g, distribution="rectangular")
    b.add("Resolution of the rotary encoder", 0.0101, 1.0, 50, group=g, distribution="rectangular")
    b.add("Residual setup error calculation", 0.0001, 1.0, 50, group=g, distribution="rectangular")
    b.add("Repeatability of the pitch angle deviation measurement", 0.0490, estler_sensitivity(24), 5, distribution="t")
    b.add("setup error uncertainty", 0.0144, 1.0, 50, distribution="rectangular")
    return b
