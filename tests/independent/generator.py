"""An independent generator of bench datasets (issue 16, item 1): the loop on data it has never seen.

Nothing here is imported from ``benchtwin.twin`` or ``benchtwin.analysis`` (not the dataset writer,
not the renderer, not a Fourier helper): the geometry, the tables, the CSV / JSON / PNG writers and
the CCD rasteriser are written again from the documents alone —

- docs/dataset-format.md (the tables, the manifest) and docs/conventions.md (lab frame, signs);
- Jia et al. 2019 for the bench: head on +Y at radius r, two test spheres at L1 and L2, a CCD at
  180° looking at the outer end of the graduation lines (sec. 4.2);
- Hsieh et al. 2022 eq. 3 for the polygon: ε_ij = α((i−1)·360/N + S) + Σ_{k=j}^{j+i−1} β_k + U_j,
  and eq. 8 for the multi-head differences δ_(1,j) = a_1 − a_j.

**Exact geometry.** The disk's centre in the lab at true rotation φ is
c(φ) = e·(cos(90° − θ0 + φ), sin(90° − θ0 + φ)) + m(φ), with m the shaft's motion at the disk plane
(a rigid shaft: linear between the two spheres' motions). A head at lab polar angle γ = 90° + ψ and
radius r_h reads the graduation on the radial line from c through its position, so its reading
error is a = γ − atan2(P − c) + G(graduation value), exactly (for e alone and r_h = r this is
atan2(e·sin(φ − θ0), r − e·cos(φ − θ0)); the textbook closed form asin((e/r)·sin(φ − θ0)) describes
a head that stays at r from the disk centre and differs from it by < e²/(2r²) ≈ 0.02″). G is the
division error, Σ A_k·sin(kθ + p_k). The servo holds head 1's reading at the commanded stop, so the
true angle solves φ + a_1(φ) = θ_stop (fixed point, converged to 1e-15 rad). The probes read the
sphere surface along +Y (and +X): the sphere centre's centring on the shaft + the motion at its
height + the form of the surface at the contact point (a function of the sphere's body angle) +
noise. The autocollimator reads the face angle x = α + Σβ + U through its own response
x·(1 + g) + q·x² + drift·t + noise. The CCD sees the lines' outer ends on a circle of radius
R_edge about c (docs/conventions.md "CCD image axes"), rasterised here by supersampling.

Each :class:`Case` names the bench, what it hides and the verdicts that are correct
(:meth:`Case.correct`): a named effect, or an allowed ambiguity set (``must`` ⊆ verdict ⊆
``must`` ∪ ``may``). The truth (the encoder's true error α(θ) of head 1 on a 0.1° grid, the hidden
parameters) is returned and written beside the dataset (``<case>/truth.json``), never inside it.
"""

from __future__ import annotations

import json
import math
import os
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ARCSEC_RAD = math.pi / 648000.0  # 1″ in rad (definition)

# The bench (Jia 2019 sec. 5 values where given; the rest as the project's scenarios assume).
R_MM = 22.0            # optical radius r of the head (eq. 5)
R_EDGE_MM = 22.5       # outer end of the graduation lines seen by the CCD
L1_MM, L2_MM = 6.81, 122.96   # top sphere -> disk, top sphere -> bottom sphere (sec. 5)
PERIOD_UM = 20.0       # grating period at the edge (sec. 4.2.2)
LINE_MM = 1.2          # radial length of a graduation line
N_FACES = 23           # polygon (sec. 4.3)
E_UM, THETA0_DEG = 7.1, 192.08   # eccentricity and its phase (sec. 5)
CENTRING = ((3.0, 40.0), (4.5, 300.0))  # sphere centrings on the shaft: (µm, deg), top and bottom
PROBE_NOISE_UM = 0.02  # probe repeatability (1 σ) of this generator's probes
AC_NOISE_ARCSEC = 0.04  # autocollimator reading noise (1 σ)
HEAD_NOISE_ARCSEC = 0.03  # noise of one head difference δ (1 σ)
AC_RES, AC_ACC = 0.005, 0.25   # TriAngle data sheet (Hsieh/Jia): resolution, accuracy, arcsec
STOP_S = 2.5           # time per polygon stop (move + dwell), s
# CCD: small frames (as tests/analysis/test_jia_external_dataset.py) at 2 µm/px
PX_UM, W_PX, H_PX = 2.0, 480, 360
CCD_STEP_DEG = 15.0


# --------------------------------------------------------------------------------------------
# writers (docs/dataset-format.md: CSV with a header row, floats in shortest round-trip repr;
# every file written to a temporary name and renamed; the manifest last)
# --------------------------------------------------------------------------------------------
def _atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name("." + path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _cell(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        raise TypeError("no booleans in tables")
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        if not math.isfinite(x):
            raise ValueError("non-finite value")
        return repr(x)
    return str(v)


def write_csv(path: Path, columns: dict[str, list]) -> None:
    names = list(columns)
    n = len(columns[names[0]])
    lines = [",".join(names)]
    for i in range(n):
        lines.append(",".join(_cell(columns[c][i]) for c in names))
    _atomic(path, ("\n".join(lines) + "\n").encode("utf-8"))


def write_png_grey8(path: Path, img: np.ndarray) -> None:
    """An 8-bit greyscale PNG (ISO/IEC 15948: signature, IHDR, one IDAT, IEND; filter 0 per row)."""
    a = np.ascontiguousarray(img, dtype=np.uint8)
    h, w = a.shape

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    _atomic(path, png)


# --------------------------------------------------------------------------------------------
# the bench's physics
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Physics:
    """What the generated bench does (all defaults: a clean bench with eccentricity only)."""
    #: whirls of the shaft [(k, amplitude_um, phase_deg, top_scale, bottom_scale)]: the sphere at
    #: height z moves by scale·a·(cos(kφ − ψ), sin(kφ − ψ)) (a k-lobed race: a whirl)
    whirls: tuple = ()
    #: form of a sphere's surface: [(sphere "top"|"bottom", k, amplitude_um, phase_deg)] as a
    #: function of the sphere's body angle at the contact point
    form: tuple = ()
    #: division error G(θ) = Σ A·sin(kθ + p): [(k, amplitude_arcsec, phase_deg)]
    graduation: tuple = ()
    head_radius_mm: float = R_MM        # the true r of the heads (the manifest says R_MM)
    ac_gain: float = 0.0                # autocollimator scale error (relative)
    ac_quad_per_arcsec: float = 0.0     # autocollimator quadratic non-linearity q (reading += q·x²)
    ac_drift_arcsec_per_s: float = 0.0  # autocollimator zero drift


@dataclass(frozen=True)
class Design:
    """What the generated bench measures."""
    x_probes: bool = True
    heads_deg: tuple = (0.0,)
    shifts_deg: tuple = (0.0,)          # all start faces at the first shift, start face 1 at the others
    directions: tuple = ("forward",)
    reps: int = 1
    radial_reps: int = 3
    radial_positions: int = 120
    selfcal_step_deg: float = 2.0       # head differences every this many degrees (≥ 3 heads)
    setup_error_arcsec: float = 3.0     # spread (1 σ) of the setup errors U_j
    #: the encoder's display step: the servo holds the count nearest to each stop, the display
    #: (polygon.csv ``theta_read_deg``) differs from the stop by up to half of it (0: exact display)
    encoder_resolution_arcsec: float = 0.0
    polygon_pitch_rms_arcsec: float = 0.8


def _motion_at(phys: Physics, phi: np.ndarray, z_weight_top: float) -> tuple[np.ndarray, np.ndarray]:
    """Shaft motion (x, y) in µm at a height between the spheres (weight of the top sphere's motion)."""
    mx = np.zeros_like(phi)
    my = np.zeros_like(phi)
    for k, a, p, s_top, s_bot in phys.whirls:
        s = z_weight_top * s_top + (1.0 - z_weight_top) * s_bot
        arg = k * phi - math.radians(p)
        mx = mx + s * a * np.cos(arg)
        my = my + s * a * np.sin(arg)
    return mx, my


#: the disk's weight on the top sphere's motion (rigid shaft, docs/conventions.md "Spheres")
W_DISK_TOP = (L2_MM - L1_MM) / L2_MM


def disk_centre_um(phys: Physics, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = math.radians(90.0 - THETA0_DEG) + phi
    mx, my = _motion_at(phys, phi, W_DISK_TOP)
    return E_UM * np.cos(a) + mx, E_UM * np.sin(a) + my


def graduation_arcsec(phys: Physics, theta_rad: np.ndarray) -> np.ndarray:
    g = np.zeros_like(theta_rad)
    for k, a, p in phys.graduation:
        g = g + a * np.sin(k * theta_rad + math.radians(p))
    return g


def head_error_rad(phys: Physics, phi: np.ndarray, psi_deg: float) -> np.ndarray:
    """Exact reading error of the head at ψ from head 1 at true rotation φ (rad)."""
    gam = math.radians(90.0 + psi_deg)
    cx, cy = disk_centre_um(phys, phi)
    rh = phys.head_radius_mm * 1000.0
    lam = np.arctan2(rh * math.sin(gam) - cy, rh * math.cos(gam) - cx)
    geo = np.angle(np.exp(1j * (gam - lam)))  # wrapped to (−π, π]
    # the graduation under the head carries the value head 1 read at φ − ψ (docs/conventions.md)
    return geo + graduation_arcsec(phys, phi - math.radians(psi_deg) + geo) * ARCSEC_RAD


def true_angle_rad(phys: Physics, theta_stop_deg: np.ndarray) -> np.ndarray:
    """φ with φ + a_1(φ) = θ_stop: the servo holds head 1's reading."""
    th = np.radians(np.asarray(theta_stop_deg, dtype=float))
    phi = th.copy()
    for _ in range(50):
        new = th - head_error_rad(phys, phi, 0.0)
        if np.max(np.abs(new - phi)) < 1e-15:
            phi = new
            break
        phi = new
    return phi


def encoder_error_arcsec(phys: Physics, theta_deg: np.ndarray) -> np.ndarray:
    """The true α(θ) of head 1 at its reading θ (what the calibration should find)."""
    phi = true_angle_rad(phys, theta_deg)
    return (np.radians(np.asarray(theta_deg, dtype=float)) - phi) / ARCSEC_RAD


def probe_readings_um(phys: Physics, phi: np.ndarray, sphere: str, axis: str, rng: np.random.Generator,
                      offset_um: float) -> np.ndarray:
    w = 1.0 if sphere == "top" else 0.0
    mx, my = _motion_at(phys, phi, w)
    cen, cph = CENTRING[0] if sphere == "top" else CENTRING[1]
    ca = phi + math.radians(cph)
    centre = (cen * np.cos(ca) + mx) if axis == "x" else (cen * np.sin(ca) + my)
    # contact point: on +Y (lab angle 90°) or +X (0°); its body angle = lab angle − φ
    body = (math.pi / 2 if axis == "y" else 0.0) - phi
    f = np.zeros_like(phi)
    for s, k, a, p in phys.form:
        if s == sphere:
            f = f + a * np.cos(k * body - math.radians(p))
    return offset_um + centre + f + rng.normal(0.0, PROBE_NOISE_UM, phi.size)


# --------------------------------------------------------------------------------------------
# CCD rasteriser: radial chrome lines on glass, ending on the circle R_edge about the disk centre
# --------------------------------------------------------------------------------------------
def _chrome_fraction(xs: np.ndarray, ys: np.ndarray, cx: float, cy: float, phi: float) -> np.ndarray:
    """Fraction of chrome at image points (xs, ys) (any shape; the last axis is averaged)."""
    # camera at 180° from the head: radial unit u = lab −Y, image +y = ẑ × u = lab +X
    ux, uy = 0.0, -1.0
    vx, vy = -uy, ux
    R = R_EDGE_MM * 1000.0
    px = R * ux + (xs - W_PX / 2) * PX_UM * ux + (ys - H_PX / 2) * PX_UM * vx
    py = R * uy + (xs - W_PX / 2) * PX_UM * uy + (ys - H_PX / 2) * PX_UM * vy
    dx, dy = px - cx, py - cy
    rho = np.hypot(dx, dy)
    pitch = PERIOD_UM / R
    u = (np.arctan2(dy, dx) - phi) / pitch
    chrome = (rho <= R) & (rho >= R - LINE_MM * 1000.0) & ((u - np.floor(u)) < 0.5)
    return chrome.mean(axis=-1)


def render_frame(phys: Physics, phi: float, rng: np.random.Generator) -> np.ndarray:
    cx, cy = disk_centre_um(phys, np.array([phi]))
    cx, cy = float(cx[0]), float(cy[0])
    yy, xx = np.mgrid[0:H_PX, 0:W_PX].astype(float)

    def sample(sel_y, sel_x, s):
        off = (np.arange(s) + 0.5) / s - 0.5
        ox, oy = np.meshgrid(off, off)
        X = sel_x[..., None] + ox.ravel()
        Y = sel_y[..., None] + oy.ravel()
        return _chrome_fraction(X, Y, cx, cy, phi)

    # pixel corners: a pixel whose four corners agree (and whose neighbours' do) is uniform; the
    # others are averaged over 4 × 4 samples
    cy_, cx_ = np.mgrid[0:H_PX + 1, 0:W_PX + 1].astype(float) - 0.5
    corner = _chrome_fraction(cx_[..., None], cy_[..., None], cx, cy, phi)
    c00, c01, c10, c11 = corner[:-1, :-1], corner[:-1, 1:], corner[1:, :-1], corner[1:, 1:]
    mixed = (c00 != c01) | (c00 != c10) | (c00 != c11)
    grown = mixed.copy()
    grown[1:, :] |= mixed[:-1, :]
    grown[:-1, :] |= mixed[1:, :]
    grown[:, 1:] |= mixed[:, :-1]
    grown[:, :-1] |= mixed[:, 1:]
    cover = c00.copy()
    iy, ix = np.nonzero(grown)
    cover[iy, ix] = sample(iy.astype(float), ix.astype(float), 4)
    R = R_EDGE_MM * 1000.0
    rho = np.hypot((yy - H_PX / 2) * PX_UM - cx, -R - (xx - W_PX / 2) * PX_UM - cy)
    band = np.abs(rho - R) < 2.0 * PX_UM
    iy, ix = np.nonzero(band)
    cover[iy, ix] = sample(iy.astype(float), ix.astype(float), 16)
    glass, chrome = 200.0, 30.0
    img = glass + (chrome - glass) * cover + rng.normal(0.0, 1.0, cover.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------------------------
# the dataset
# --------------------------------------------------------------------------------------------
def generate(path: Path, phys: Physics, design: Design, seed: int, *, ccd: bool = True) -> dict[str, Any]:
    """Write one dataset at ``path`` (docs/dataset-format.md); return the truth."""
    rng = np.random.default_rng(seed)
    path = Path(path)
    if path.exists() and any(path.iterdir()):
        raise FileExistsError(f"{path}: not empty")
    path.mkdir(parents=True, exist_ok=True)
    # radial motion: revolutions of stops, both spheres (Y, and X with X probes)
    th = np.arange(design.radial_positions) * 360.0 / design.radial_positions
    offs = rng.uniform(-5, 5, 4)
    rm: dict[str, list] = {"rep": [], "theta_deg": [], "probe_top_um": [], "probe_bottom_um": []}
    if design.x_probes:
        rm.update({"probe_top_x_um": [], "probe_bottom_x_um": []})
    for rep in range(design.radial_reps):
        phi = true_angle_rad(phys, th)
        rm["rep"] += [rep] * th.size
        rm["theta_deg"] += th.tolist()
        rm["probe_top_um"] += probe_readings_um(phys, phi, "top", "y", rng, offs[0]).tolist()
        rm["probe_bottom_um"] += probe_readings_um(phys, phi, "bottom", "y", rng, offs[1]).tolist()
        if design.x_probes:
            rm["probe_top_x_um"] += probe_readings_um(phys, phi, "top", "x", rng, offs[2]).tolist()
            rm["probe_bottom_x_um"] += probe_readings_um(phys, phi, "bottom", "x", rng, offs[3]).tolist()
    write_csv(path / "radial_motion.csv", rm)
    # CCD sweep
    if ccd:
        thc = np.arange(0.0, 360.0, CCD_STEP_DEG)
        phic = true_angle_rad(phys, thc)
        files = []
        for k, ph in enumerate(phic):
            files.append(f"frame_{k:03d}.png")
            write_png_grey8(path / "ccd" / files[-1], render_frame(phys, float(ph), rng))
        write_csv(path / "ccd" / "index.csv", {"k": list(range(thc.size)), "theta_deg": thc.tolist(), "file": files})
    # polygon (Hsieh eq. 3) through the autocollimator's response
    N = N_FACES
    beta = rng.normal(0.0, design.polygon_pitch_rms_arcsec, N)
    beta -= beta.mean()
    pc: dict[str, list] = {k: [] for k in ("shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s",
                                           "rep", "direction")}
    t = 0.0
    for rep in range(design.reps):
        for si, S in enumerate(design.shifts_deg):
            faces = range(1, N + 1) if si == 0 else (1,)
            for j in faces:
                U = rng.normal(0.0, design.setup_error_arcsec)  # a new mounting per run
                for d in design.directions:
                    steps = list(range(1, N + 1)) if d == "forward" else list(range(N, 0, -1))
                    thi = np.array([((i - 1) * 360.0 / N + S) % 360.0 for i in steps])
                    res = design.encoder_resolution_arcsec
                    shown = np.round(thi * 3600.0 / res) * res / 3600.0 if res > 0 else thi
                    # the polygon stands at the true angle of the displayed count, φ = θ_read − α(θ_read);
                    # its face angle from the nominal stop θ_i is θ_i − φ = α + (θ_i − θ_read)
                    alpha = encoder_error_arcsec(phys, shown) + (thi - shown) * 3600.0
                    for n, i in enumerate(steps):
                        bsum = sum(beta[(j - 1 + m) % N] for m in range(i))
                        x = alpha[n] + bsum + U
                        eps = (x * (1.0 + phys.ac_gain) + phys.ac_quad_per_arcsec * x * x
                               + phys.ac_drift_arcsec_per_s * t + rng.normal(0.0, AC_NOISE_ARCSEC))
                        for key, v in (("shift_deg", float(S)), ("start_face", j), ("step", i),
                                       ("theta_deg", float(thi[n])), ("ac_arcsec", round(float(eps), 4)),
                                       ("t_s", t), ("rep", rep), ("direction", d)):
                            pc[key].append(v)
                        if res > 0:
                            pc.setdefault("theta_read_deg", []).append(float(shown[n]))
                        t += STOP_S
    write_csv(path / "polygon.csv", pc)
    # multi-head differences (Hsieh eq. 8) with ≥ 3 heads
    if len(design.heads_deg) >= 3:
        ths = np.arange(0.0, 360.0, design.selfcal_step_deg)
        phis = true_angle_rad(phys, ths)
        a1 = head_error_rad(phys, phis, 0.0) / ARCSEC_RAD
        hc: dict[str, list] = {"theta_deg": [], "head": [], "delta_arcsec": []}
        for h, psi in enumerate(design.heads_deg, start=1):
            d = a1 - head_error_rad(phys, phis, psi) / ARCSEC_RAD
            if h > 1:
                d = d + rng.normal(0.0, HEAD_NOISE_ARCSEC, d.size)
            hc["theta_deg"] += ths.tolist()
            hc["head"] += [h] * ths.size
            hc["delta_arcsec"] += [round(float(x), 4) for x in d]
        write_csv(path / "heads.csv", hc)
    bench: dict[str, Any] = {"optical_radius_mm": R_MM, "L1_mm": L1_MM, "L2_mm": L2_MM,
                             "grating_period_um": PERIOD_UM, "polygon_faces": N, "scale_edge_radius_mm": R_EDGE_MM,
                             "autocollimator_resolution_arcsec": AC_RES, "autocollimator_accuracy_arcsec": AC_ACC}
    if design.encoder_resolution_arcsec > 0:
        bench["encoder_resolution_arcsec"] = design.encoder_resolution_arcsec
    if len(design.heads_deg) >= 3:
        bench["heads_deg"] = [float(x) for x in design.heads_deg]
    manifest: dict[str, Any] = {"format": "bench-dataset", "version": 1, "source": "external", "bench": bench,
                                "created_by": "tests/independent/generator.py", "seed": int(seed)}
    if ccd:
        manifest["ccd"] = {"position_deg": 180.0, "outward": "+x", "tangential": "+x",
                           "reference_px": [W_PX / 2, H_PX / 2], "pixel_um": PX_UM}
    _atomic(path / "manifest.json", (json.dumps(manifest, indent=1) + "\n").encode("utf-8"))
    grid = np.arange(0.0, 360.0, 0.1)
    return {"theta_deg": grid.tolist(), "alpha_arcsec": encoder_error_arcsec(phys, grid).tolist(),
            "beta_arcsec": beta.tolist()}


# --------------------------------------------------------------------------------------------
# the cases and their correct verdicts
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    name: str
    what: str
    build: Callable[[np.random.Generator], Physics]   # the hidden physics, drawn from the seed
    design: Design
    must: frozenset = frozenset()       # the verdict must contain these …
    may: frozenset = frozenset()        # … and may contain these (an allowed ambiguity set)
    why: str = ""
    corrected: bool = False             # a reference-chain effect: the corrected curve is checked
    meta: dict = field(default_factory=dict)

    def correct(self, verdict: dict[str, Any]) -> bool:
        """``verdict``: {"effects": set of names (identified ∪ ambiguity sets), "unexplained": bool}."""
        if verdict["unexplained"]:
            return False
        eff = set(verdict["effects"])
        return self.must <= eff <= (self.must | self.may)


def verdict_of(results: dict[str, Any]) -> dict[str, Any]:
    """The analysis's verdict from results.json: every effect it names or leaves in a set."""
    eff = {str(e["name"]) for e in results.get("identified_effects") or []}
    for a in results.get("ambiguous") or []:
        eff |= {str(n) for n in (a.get("names", []) if isinstance(a, dict) else a)}
    return {"effects": eff, "unexplained": bool(results.get("unexplained")),
            "named": sorted(str(e["name"]) for e in results.get("identified_effects") or [])}


def _fs(*names: str) -> frozenset:
    return frozenset(names)


def _graduation_small(rng):
    return tuple((k, float(rng.uniform(0.04, 0.15)), float(rng.uniform(0, 360))) for k in range(3, 9))


CASES: dict[str, Case] = {c.name: c for c in [
    Case("null_xy", "nothing hidden; X and Y probes, one head", lambda r: Physics(), Design(x_probes=True),
         why="no effect named"),
    Case("null_y", "nothing hidden; Y probes only, 3 heads, both directions, 2 reps; 0.39″ display", lambda r: Physics(),
         Design(x_probes=False, heads_deg=(0.0, 120.0, 240.0), directions=("forward", "backward"), reps=2,
                encoder_resolution_arcsec=0.39),
         why="no effect named (no sphere form is present)"),
    Case("graduation", "division error k = 2, 3, 5 (0.5, 0.3, 0.2″); X probes",
         lambda r: Physics(graduation=((2, 0.5, float(r.uniform(0, 360))), (3, 0.3, float(r.uniform(0, 360))),
                                       (5, 0.2, float(r.uniform(0, 360))))),
         Design(x_probes=True), must=_fs("graduation_error"), why="named (X probes rule out a motion)"),
    Case("head_radius", "true head radius 2 % above the data sheet's (22.44 mm)",
         lambda r: Physics(head_radius_mm=R_MM * 1.02), Design(x_probes=True), must=_fs("optical_radius"),
         may=_fs("ccd_pixel_scale", "ac_scale", "interpolation_error"),
         why="named or ambiguous with ccd_pixel_scale / ac_scale (polygon data alone: gains on the model and on α) "
             "and interpolation_error (L = 2πr/p = 6912 lines: its 2nd order aliases onto k = 1 on 23 faces, "
             "2·6912 mod 23 = 1, the eccentricity's harmonic)"),
    Case("ac_drift", "autocollimator drift 20″/h; forward and backward sweeps",
         lambda r: Physics(ac_drift_arcsec_per_s=20.0 / 3600.0), Design(x_probes=True, directions=("forward", "backward")),
         must=_fs("ac_drift"), why="named (backward sweeps)", corrected=True),
    Case("tangential", "k = 2 whirl of 0.15 µm and k = 3 of 0.08 µm; X probes",
         lambda r: Physics(whirls=((2, 0.15, float(r.uniform(0, 360)), 1.0, 1.0),
                                   (3, 0.08, float(r.uniform(0, 360)), 1.0, 1.0))),
         Design(x_probes=True), must=_fs("tangential_motion"), why="named (X probes)"),
    Case("sphere_form", "top sphere 2- and 3-lobed form 0.15 / 0.10 µm; Y probes only",
         lambda r: Physics(form=(("top", 2, 0.15, float(r.uniform(0, 360))), ("top", 3, 0.10, float(r.uniform(0, 360))))),
         Design(x_probes=False), must=_fs("sphere_form"), may=_fs("graduation_error", "tangential_motion"),
         why="sphere_form, or in a set with graduation_error / tangential_motion (a Donaldson reversal separates)"),
    Case("ac_nonlinearity", "autocollimator reading += q·x², q drawn in 2…4·10⁻⁴/″ (1–2″ at ±70″); 3 heads; 0.39″ display",
         lambda r: Physics(ac_quad_per_arcsec=float(r.uniform(2e-4, 4e-4))),
         Design(x_probes=False, heads_deg=(0.0, 120.0, 240.0), encoder_resolution_arcsec=0.39), must=_fs("ac_scale"),
         why="named (the self-calibration rules out encoder causes)", corrected=True),
    Case("jia_like", "Jia's bench: 2/3/5-lobed whirls 0.15/0.10/0.05 µm of the top bearing, Y probes only",
         lambda r: Physics(whirls=((2, 0.15, float(r.uniform(0, 360)), 1.0, 0.3),
                                   (3, 0.10, float(r.uniform(0, 360)), 1.0, 0.3),
                                   (5, 0.05, float(r.uniform(0, 360)), 1.0, 0.3))),
         Design(x_probes=False), must=_fs("tangential_motion"), may=_fs("graduation_error", "sphere_form", "tilt_abbe"),
         why="{tangential_motion, graduation_error, sphere_form} (no X probes: an X motion reads like a division "
             "error, and a form read as motion leaves ∫f/r, per lobe the same cos(kθ − ψ) as (1 − 1/k)·δX/r)"),
    Case("selfa_like", "SelfA-like: 12 heads, shifts 0…14°, k = 2 division error 1″ + k = 3…8 of 0.04–0.15″; 0.39″ display",
         lambda r: Physics(graduation=((2, 1.0, float(r.uniform(0, 360))),) + _graduation_small(r)),
         Design(x_probes=True, heads_deg=tuple(30.0 * h for h in range(12)),
                shifts_deg=tuple(float(s) for s in range(15)), encoder_resolution_arcsec=0.39),
         must=_fs("graduation_error"), why="named (12-head self-calibration, X probes)"),
]}

#: the default suite's cases (the rest run behind @pytest.mark.slow)
FAST = ("null_y", "selfa_like", "ac_nonlinearity")


def write_case(case: Case, root: Path, seed: int) -> tuple[Path, dict[str, Any]]:
    """Write ``root/<case>/seed<seed>/dataset`` and its truth.json beside it."""
    rng = np.random.default_rng([seed, 16])  # the hidden parameters: a stream apart from the noise
    phys = case.build(rng)
    d = Path(root) / case.name / f"seed{seed}"
    truth = generate(d / "dataset", phys, case.design, seed)
    truth["physics"] = {k: getattr(phys, k) for k in phys.__dataclass_fields__}
    _atomic(d / "truth.json", (json.dumps(truth) + "\n").encode("utf-8"))
    return d / "dataset", truth


def corrected_check(results: dict[str, Any], truth: dict[str, Any], k: float = 2.0) -> dict[str, Any] | None:
    """Is the corrected curve (``encoder_error_corrected_arcsec``) within k·u of the true α?

    α from a polygon is known up to one constant (Hsieh eq. 2: Σα = 0 per run), so the weighted mean
    difference is removed first. Correct when ≥ 95 % of the curve's points lie within k·u (the
    coverage a k = 2 interval states); the worst |d|/u is reported too. None without a curve."""
    c = results.get("encoder_error_corrected_arcsec")
    if not c:
        return None
    th = np.asarray(c["theta_deg"], dtype=float)
    v = np.asarray(c["value"], dtype=float)
    u = np.asarray(c["u"], dtype=float)
    g = np.asarray(truth["theta_deg"], dtype=float)
    a = np.asarray(truth["alpha_arcsec"], dtype=float)
    t = np.interp(np.mod(th, 360.0), np.concatenate([g, [360.0]]), np.concatenate([a, a[:1]]))
    d = v - t
    w = 1.0 / u ** 2
    d = d - np.sum(w * d) / np.sum(w)
    z = np.abs(d) / u
    raw = results.get("encoder_error_arcsec") or {}
    out = {"within_frac": float(np.mean(z <= k)), "max_z": float(np.max(z)),
           "rms_arcsec": float(np.sqrt(np.mean(d ** 2))), "u_rms_arcsec": float(np.sqrt(np.mean(u ** 2))),
           "applied": [x.get("effect") for x in c.get("corrections_applied") or []]}
    if raw:
        dr = np.asarray(raw["value"], dtype=float) - t
        out["raw_rms_arcsec"] = float(np.sqrt(np.mean((dr - np.mean(dr)) ** 2)))
    out["ok"] = out["within_frac"] >= 0.95
    return out
