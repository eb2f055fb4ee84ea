"""Geometry of the rotary scale near its edge, as the CCD microscope of Jia 2019 sec. 4.2 sees it.

Jia et al., Appl. Sci. 9 (2019) 3415, sec. 4.2.1–4.2.2: a microscope with a 2048×1536 px CCD
(0.667 µm/px object side) looks through a hole opposite the reading head at the outer ends of the
radial graduation lines ("rotary scales edge"); 60 images, one every 6°, give the disk's geometric
centre by a circle fit through the line ends.

What is modelled, and why:

- lines: radial chrome strips of angular pitch ``2π/N`` with ``N = round(2π·R_edge/period)`` (the
  catalogue period is the period at the scale edge, sec. 4.2.2 "grating period is 20 µm"), centred
  on the graduation angles ``g_k = k·pitch`` (docs: the graduation at body angle g lies along body
  direction (cos g, sin g, 0)), of angular width ``duty·pitch``, from ``R_edge − line_length`` to
  ``R_edge``. The outer end is the arc r = R_edge, split into ``n_arc`` chords (sagitta of a
  15 px wide end is 8e-4 px already; 4 chords make it 5e-5 px); the inner end (outside the view
  for the Jia geometry) is one chord. Each line is thus a *convex* polygon: both backends draw
  exactly these polygons, so they can be compared to the rasteriser's accuracy;
- glass: everything that is not chrome (zero coverage; transmitted light, so glass is the bright
  level). The disk's outer rim, 2 mm beyond the scale edge in ``twin/build.py``, is outside the
  ±0.68 mm view, so no rim is drawn: the "edge" Jia fits is the scale edge, the line ends;
- only lines whose angular range meets the field of view plus a margin are built (about 60 of the
  7069 lines), so a frame costs the same whatever the disk size;
- the camera is telecentric (orthographic along the lab z axis): a microscope objective at this
  magnification has a depth of field of a few µm and its image scale does not change with the
  sub-µm axial motion, so the disk's tilt only foreshortens (cos tilt) and never magnifies;
- precision: vertices are computed in float64 in the lab frame, then expressed in CAMERA-LOCAL
  pixel coordinates (the look-at point subtracted in float64) before any float32 conversion; at
  ≤ 2000 px from the origin float32 keeps 1e-4 px, whereas lab coordinates (22.5 mm) in float32
  would quantise positions to 2 nm = 0.003 px and, worse, the look-at subtraction would cancel.

Camera and image axes (docs/conventions.md, "CCD image axes"): the camera sits at azimuth ψ from
the head (head on +Y): radial unit u = (cos(90°+ψ), sin(90°+ψ), 0). Image +x = u (outward);
image +y = s·(ẑ × u), s = +1 for ``tangential = "+x"`` (at ψ = 180°, ẑ × u = +X, the direction the
disk surface moves for positive rotation). A camera rotation ρ about its axis turns both image
axes by ρ (from +x towards +y); a pixel-scale error ε makes the true object-side pixel
``pixel_pitch·(1 + ε)``. The look-at point (radius ``look_at_radius_m`` on u, in the disk plane)
is imaged on the reference point R = (W/2, H/2) (Jia: (1024, 768)). Pixel (x, y) = (column, row)
with the origin at the centre of the top-left pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from benchtwin.twin.pose import BodyPose

__all__ = ["GratingSpec", "CcdCamera", "SceneGeometry", "build_scene", "to_trimesh", "fan_arrays"]


@dataclass(frozen=True)
class GratingSpec:
    """The radial grating near its outer edge (SI units)."""

    period_m: float
    duty: float
    line_length_m: float
    edge_radius_m: float
    chrome_transmission: float = 0.03  # opaque chrome; the residual is flare through the optics
    glass_transmission: float = 1.0  # bright level = glass (normalised)

    def __post_init__(self) -> None:
        if not (0.0 < self.duty < 1.0):
            raise ValueError(f"grating duty must be in (0, 1), got {self.duty}")
        if not (0.0 < self.line_length_m < self.edge_radius_m):
            raise ValueError("grating line length must be positive and shorter than the edge radius")
        if self.period_m <= 0.0:
            raise ValueError(f"grating period must be positive, got {self.period_m}")

    @property
    def n_lines(self) -> int:
        return int(round(2.0 * math.pi * self.edge_radius_m / self.period_m))

    @property
    def pitch_rad(self) -> float:
        return 2.0 * math.pi / self.n_lines

    @classmethod
    def from_bench(cls, bench: dict) -> "GratingSpec":
        """From the SI-parsed ``[bench]`` section of a scenario."""
        return cls(period_m=float(bench["grating_period"]), duty=float(bench["grating_duty"]),
                   line_length_m=float(bench["grating_line_length"]),
                   edge_radius_m=float(bench["scale_edge_radius"]))


@dataclass(frozen=True)
class CcdCamera:
    """The microscope + CCD as a geometric camera (orthographic, telecentric)."""

    azimuth_rad: float
    look_at_radius_m: float | None = None  # None: the grating's edge radius
    width_px: int = 2048
    height_px: int = 1536
    pixel_pitch_m: float = 0.667e-6  # nominal object-side pixel (what the analysis assumes)
    rotation_rad: float = 0.0
    pixel_scale_error: float = 0.0
    tangential: str = "+x"

    def __post_init__(self) -> None:
        if self.tangential not in ("+x", "-x"):
            raise ValueError(f"tangential must be '+x' or '-x', got {self.tangential!r}")

    @property
    def reference_px(self) -> tuple[float, float]:
        return (self.width_px / 2.0, self.height_px / 2.0)

    @property
    def true_pixel_m(self) -> float:
        return self.pixel_pitch_m * (1.0 + self.pixel_scale_error)

    @classmethod
    def from_scenario(cls, bench: dict, ccd: dict, tangential: str = "+x") -> "CcdCamera":
        """From the SI-parsed ``[bench]`` and ``[instruments.ccd]`` sections."""
        return cls(azimuth_rad=float(bench.get("ccd_position", math.pi)), width_px=int(round(ccd["width"])),
                   height_px=int(round(ccd["height"])), pixel_pitch_m=float(ccd["pixel_pitch"]),
                   rotation_rad=float(ccd.get("rotation", 0.0)),
                   pixel_scale_error=float(ccd.get("pixel_scale_error", 0.0)), tangential=tangential)

    def axes_lab(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u radial, e_x image-x direction, e_y image-y direction) as lab unit vectors."""
        a = math.pi / 2.0 + self.azimuth_rad
        u = np.array([math.cos(a), math.sin(a), 0.0])
        s = 1.0 if self.tangential == "+x" else -1.0
        t = s * np.array([-u[1], u[0], 0.0])  # s·(ẑ × u)
        c, sn = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        return u, c * u + sn * t, -sn * u + c * t

    def look_at_lab(self, edge_radius_m: float) -> np.ndarray:
        r = edge_radius_m if self.look_at_radius_m is None else self.look_at_radius_m
        return r * self.axes_lab()[0]

    def lab_to_local_px(self, p_lab: np.ndarray, edge_radius_m: float) -> np.ndarray:
        """Lab points (..., 3) → camera-local pixel coordinates (..., 2), float64, relative to the
        reference point (x right = outward, y down). Orthographic along lab z."""
        _, ex, ey = self.axes_lab()
        d = np.asarray(p_lab, dtype=np.float64) - self.look_at_lab(edge_radius_m)  # float64 cancel first
        return np.stack([d @ ex, d @ ey], axis=-1) / self.true_pixel_m

    def lab_to_px(self, p_lab: np.ndarray, edge_radius_m: float) -> np.ndarray:
        """Lab points (..., 3) → pixel coordinates (x = column, y = row)."""
        return self.lab_to_local_px(p_lab, edge_radius_m) + np.asarray(self.reference_px)


@dataclass
class SceneGeometry:
    """The frame's polygons in camera-local px (float64) and the truth that goes with them."""

    polygons: list[np.ndarray]  # each (n, 2) convex, vertices in order, camera-local px
    line_index: np.ndarray  # graduation index k of each polygon
    end_mid_px: np.ndarray  # (n_lines, 2) image px of the outer end's midpoint (arc at g_k)
    centre_px: tuple[float, float]
    edge_radius_px: float
    info: dict = field(default_factory=dict)

    def end_x_px(self, ref_px: tuple[float, float]) -> np.ndarray:
        """Image x of every outer-end vertex (the first n_arc + 1 vertices of each polygon)."""
        n = self.info.get("n_arc", 0) + 1
        if not self.polygons:
            return np.zeros(0)
        return np.concatenate([p[:n, 0] for p in self.polygons]) + ref_px[0]


def _view_angles(disk: BodyPose, camera: CcdCamera, grating: GratingSpec, margin_px: float) -> tuple[float, float]:
    """Range of body polar angles whose lines can reach the view (+margin)."""
    W, H = camera.width_px, camera.height_px
    ref = np.asarray(camera.reference_px)
    corners = np.array([[-0.5 - margin_px, -0.5 - margin_px], [W - 0.5 + margin_px, -0.5 - margin_px],
                        [W - 0.5 + margin_px, H - 0.5 + margin_px], [-0.5 - margin_px, H - 0.5 + margin_px]])
    _, ex, ey = camera.axes_lab()
    C = camera.look_at_lab(grating.edge_radius_m)
    a = camera.true_pixel_m
    xy = C[None, :] + ((corners - ref) @ np.stack([ex, ey])) * a  # lab points at z = 0
    # move each along lab z onto the (tilted) disk plane: n·(p − pos) = 0
    n = disk.R[:, 2]
    z = -((xy - disk.pos) @ n) / n[2]
    pts = xy + z[:, None] * np.array([0.0, 0.0, 1.0])
    body = disk.to_body(pts)
    ang = np.arctan2(body[:, 1], body[:, 0])
    c0 = ang[0]
    rel = np.angle(np.exp(1j * (ang - c0)))  # unwrap around the first corner
    r = np.hypot(body[:, 0], body[:, 1])
    if r.min() < grating.edge_radius_m * 0.5 or np.ptp(rel) > math.pi:
        raise ValueError("the camera view contains or is near the disk centre: not a scale-edge view")
    return c0 + rel.min(), c0 + rel.max()


def build_scene(disk: BodyPose, grating: GratingSpec, camera: CcdCamera, margin_px: float = 8.0,
                n_arc: int = 4) -> SceneGeometry:
    """Convex line polygons in camera-local px for the lines that meet the view (+ margin)."""
    lo, hi = _view_angles(disk, camera, grating, margin_px)
    p = grating.pitch_rad
    half = 0.5 * grating.duty * p
    k0 = int(math.floor((lo - half) / p))
    k1 = int(math.ceil((hi + half) / p))
    ks = np.arange(k0, k1 + 1)
    g = ks * p
    R, r_in = grating.edge_radius_m, grating.edge_radius_m - grating.line_length_m
    # body-frame outline per line: outer arc from g+half down to g−half (n_arc chords), then inner chord
    t = np.linspace(half, -half, n_arc + 1)
    ang_out = g[:, None] + t[None, :]
    outer = np.stack([R * np.cos(ang_out), R * np.sin(ang_out)], axis=-1)
    ang_in = g[:, None] + np.array([-half, half])[None, :]
    inner = np.stack([r_in * np.cos(ang_in), r_in * np.sin(ang_in)], axis=-1)
    outline = np.concatenate([outer, inner], axis=1)  # (nk, n_arc+3, 2)
    body = np.concatenate([outline, np.zeros(outline.shape[:-1] + (1,))], axis=-1)
    lab = disk.to_lab(body.reshape(-1, 3))
    local = camera.lab_to_local_px(lab, R).reshape(outline.shape)
    # keep polygons whose bbox meets the view (+margin)
    ref = np.asarray(camera.reference_px)
    lo_px = -ref - 0.5 - margin_px
    hi_px = np.array([camera.width_px, camera.height_px]) - ref - 0.5 + margin_px
    keep = np.all(local.max(axis=1) >= lo_px, axis=1) & np.all(local.min(axis=1) <= hi_px, axis=1)
    mid_body = np.stack([R * np.cos(g), R * np.sin(g), np.zeros_like(g)], axis=-1)
    end_mid = camera.lab_to_px(disk.to_lab(mid_body), R)
    centre = camera.lab_to_px(disk.pos, R)
    return SceneGeometry(polygons=[local[i] for i in np.flatnonzero(keep)], line_index=ks[keep],
                         end_mid_px=end_mid[keep], centre_px=(float(centre[0]), float(centre[1])),
                         edge_radius_px=R / camera.true_pixel_m,
                         info={"n_lines_total": grating.n_lines, "pitch_rad": p, "n_arc": n_arc})



def to_trimesh(polygons: list[np.ndarray], offset_px: tuple[float, float] = (0.0, 0.0), flip_y: bool = True,
               z: float = 0.0):
    """Triangle-fan mesh of convex polygons (camera-local px → GL world units, float32).

    ``offset_px`` is added in float64 before the float32 conversion; ``flip_y`` turns image y (down)
    into GL y (up). Returns a ``trimesh.Trimesh`` (not processed: no vertex merging or reordering).
    Vertices and faces come in the polygons' order, each polygon's fan from its vertex 0.
    """
    import trimesh

    V, F = fan_arrays(polygons, offset_px, flip_y, z)
    return trimesh.Trimesh(vertices=V, faces=F, process=False)


def fan_arrays(polygons: list[np.ndarray], offset_px: tuple[float, float] = (0.0, 0.0), flip_y: bool = True,
               z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(vertices float32 (N, 3), faces int (M, 3)) of ``to_trimesh``.

    Why arrays: a frame's ~55 polygons were assembled one by one (≈ 3 ms of Python per frame);
    polygons with the same vertex count (all of them: ``build_scene`` gives n_arc + 3 each) are
    done at once, with the same float64 operations per element, so the float32 vertices are the
    same bits. Faces: a fan from vertex 0, made counter-clockwise in GL coordinates (front faces).
    """
    if not polygons:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), int)
    verts, faces, base = [], [], 0
    i = 0
    while i < len(polygons):
        n = len(polygons[i])
        j = i
        while j < len(polygons) and len(polygons[j]) == n:
            j += 1
        v = np.asarray(polygons[i:j], dtype=np.float64) + np.asarray(offset_px)   # (L, n, 2)
        if flip_y:
            v = v * np.array([1.0, -1.0])
        L = j - i
        verts.append(np.concatenate([v, np.full((L, n, 1), z)], axis=2).reshape(L * n, 3))
        tri = np.column_stack([np.zeros(n - 2, int), np.arange(1, n - 1), np.arange(2, n)])
        # twice the signed area (shoelace): only its sign is used
        area = np.sum(v[:, :, 0] * np.roll(v[:, :, 1], -1, axis=1) - np.roll(v[:, :, 0], -1, axis=1) * v[:, :, 1],
                      axis=1)
        f = np.where((area > 0)[:, None, None], tri[None], tri[None, :, ::-1])
        faces.append((f + (base + n * np.arange(L))[:, None, None]).reshape(-1, 3))
        base += L * n
        i = j
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces)
