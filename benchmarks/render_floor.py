"""Render floor of a CCD frame: a bare NumPy/OpenCV rasteriser of the same frame, and the twin's own.

Issue #17: "the render of a frame ≤ 2× a bare OpenCV/numpy rasteriser of the same frame at the same
quality". The frame is the default scenario's (jia2019, 2048×1536 px) at θ = 37°, with its
eccentricity; its line polygons come from ``twin.render.grating.build_scene`` (the polygons every
backend rasterises). Quality is the line-end error against the exact coverage
(twin/render/analytic.py): the largest per-row difference of the area-method end position over
the lines in view, rows ±3 around each end (``end_error``), printed for every case. Timed here,
median of ``--repeat`` (wall and process CPU, which includes llvmpipe's threads):

- THE FLOOR (``floor_render_*``): ``area_floor.area_coverage``, the exact coverage of every pixel
  by signed-area accumulation (Green's theorem per edge and pixel column, deposits and a prefix
  sum down the columns; benchmarks/area_floor.py), its accumulation buffer kept from frame to
  frame: work in proportion to the edges' length plus one pass over the frame, nothing else; line ends exact (≤ 1e-6 px: float32), so at least the
  twin's quality (GL default ≤ 0.005 px at the ends, ≤ 1/16 px on the sides);
- for reference, the former floor (``fillpoly_*``): ``cv2.fillPoly`` on a k×-supersampled uint8
  canvas (``shift=8``) and ``cv2.resize(INTER_AREA)``, ``--k`` (default 4): 16 samples a pixel,
  ~30× worse at the line ends (≈ 0.15 px), NOT the same quality (it would need k ≈ 25);
- the floor's sensor: ``cv2.GaussianBlur`` + ``cv2.multiply`` by a vignetting map + a float32
  Gaussian noise field (``cv2.randn``) + the cast to the sensor's dtype (the operations the sensor
  model needs, nothing more);
- the twin: ``Renderer.coverage`` (default backend, GL if a context exists) and ``apply_sensor``
  (twin/render/sensor.py) on the same frame;
- all of it with the frame worker's heap (``benchtwin.heap.keep_freed_memory``: freed frame-size
  arrays reused instead of fresh pages from the kernel), ``--fresh-pages`` for glibc's default.

Prints one line per case, and with ``--json`` one JSON object on the last line (benchmarks/run_bench.py).
Usage: ``.venv/bin/python benchmarks/render_floor.py [--repeat 5] [--k 4] [--json]``
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time

import numpy as np

from benchtwin.twin.render import gl

gl.configure()

from area_floor import area_coverage, workspace  # noqa: E402  (benchmarks/, beside this script)

from benchtwin.twin.pose import BodyPose  # noqa: E402
from benchtwin.twin.render import GratingSpec, Renderer, SensorParams  # noqa: E402
from benchtwin.twin.render.analytic import coverage_image  # noqa: E402
from benchtwin.twin.render.grating import build_scene  # noqa: E402
from benchtwin.twin.render.sensor import apply_sensor  # noqa: E402
from benchtwin.twin.scenario import load_scenario  # noqa: E402


def rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def timed(fn, repeat: int) -> tuple[float, float]:
    """Median wall and median CPU seconds of ``fn()`` over ``repeat`` calls (one warm-up call)."""
    fn()
    ws, cs = [], []
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        fn()
        ws.append(time.perf_counter() - w)
        cs.append(time.process_time() - c)
    return statistics.median(ws), statistics.median(cs)


def inset(poly: np.ndarray, d: float) -> np.ndarray:
    """Convex polygon with every edge moved inward by d·(|n_x| + |n_y|) (n: the edge's unit normal).

    Why: ``cv2.fillPoly`` with sub-pixel vertices fills a scan line from round(x_left) to
    round(x_right) (and likewise in y): the pixels whose centre lies within ½ px of the polygon, not
    those whose centre it covers; an edge inset by half a canvas pixel along x and y makes it the
    centre rule (measured: the frame's total coverage then matches the exact one to 4e-4, against
    +1.7 % without the inset)."""
    P = np.asarray(poly, dtype=np.float64)
    Q = np.roll(P, -1, axis=0)
    t = Q - P
    n = np.stack([t[:, 1], -t[:, 0]], axis=1) / np.hypot(t[:, 0], t[:, 1])[:, None]
    if np.sum(P[:, 0] * Q[:, 1] - Q[:, 0] * P[:, 1]) < 0:  # clockwise: flip to the inward normal
        n = -n
    n = -n  # (t_y, −t_x) points outward for a counter-clockwise polygon
    c = np.einsum("ij,ij->i", n, P) + d * (np.abs(n[:, 0]) + np.abs(n[:, 1]))
    # vertex i = intersection of edge i−1 and edge i (lines n·x = c, with n the inward normal)
    n0, c0 = np.roll(n, 1, axis=0), np.roll(c, 1)
    det = n0[:, 0] * n[:, 1] - n0[:, 1] * n[:, 0]
    ok = np.abs(det) > 1e-12
    out = P.copy()
    out[ok, 0] = (c0[ok] * n[ok, 1] - c[ok] * n0[ok, 1]) / det[ok]
    out[ok, 1] = (n0[ok, 0] * c[ok] - n[ok, 0] * c0[ok]) / det[ok]
    return out


def cv_coverage(polygons: list[np.ndarray], w: int, h: int, ref: tuple[float, float], k: int) -> np.ndarray:
    """Coverage in [0, 1] by k×k supersampled fillPoly. Pixel (x, y) is centred on integer (x, y)
    (the analytic renderer's convention); sub-sample u of pixel x sits at (u + ½)/k − ½."""
    import cv2

    shift = 8
    canvas = np.zeros((h * k, w * k), np.uint8)
    pts = [np.round(inset((p + np.asarray(ref) + 0.5) * k - 0.5, 0.5) * (1 << shift)).astype(np.int32)
           for p in polygons]
    cv2.fillPoly(canvas, pts, 255, lineType=cv2.LINE_8, shift=shift)
    small = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA)
    return small.astype(np.float32) * np.float32(1.0 / 255.0)


def cv_sensor(irr: np.ndarray, sigma_px: float, vign: np.ndarray, max_dn: int, dtype: type) -> np.ndarray:
    """Blur, vignetting, shot+read noise (one Gaussian field), quantisation: bare OpenCV/numpy."""
    import cv2

    img = cv2.GaussianBlur(irr, (0, 0), sigma_px)
    img = cv2.multiply(img, vign)
    noise = np.empty_like(img)
    cv2.randn(noise, 0.0, 0.01)  # OpenCV's generator: the floor is the cheapest noise field of the size
    img = cv2.add(img, noise)
    return np.clip(img * np.float32(max_dn) + np.float32(0.5), 0, max_dn).astype(dtype)


def end_error(cov: np.ndarray, ref: np.ndarray, ends: np.ndarray) -> float:
    """Max |Δ| over the lines in view of the line end by the area method over rows around the end."""
    h, w = cov.shape
    d = []
    for xm, ym in ends:
        yc, x0 = int(round(ym)), int(math.floor(xm)) - 8
        if not (6 <= yc < h - 6 and 0 <= x0 and x0 + 17 < w):
            continue
        for y in range(yc - 3, yc + 4):
            d.append(float(cov[y, x0:x0 + 17].sum() - ref[y, x0:x0 + 17].sum()))
    return float(np.max(np.abs(d))) if d else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fresh-pages", action="store_true",
                    help="glibc's default heap (freed arrays come back as fresh pages) instead of the frame worker's")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--k", type=int, default=4, help="supersampling of the floor rasteriser")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not args.fresh_pages:
        # as simulate's frame worker: freed frame-size arrays reused, not faulted in again
        # (benchtwin/heap.py); otherwise page faults are ≈ half the floor's CPU
        try:
            from benchtwin.heap import keep_freed_memory
        except ImportError:   # an older package (A/B against main): say so, run on the default heap
            print("(no benchtwin.heap in this package: glibc's default heap)")
        else:
            keep_freed_memory()

    sc = load_scenario()
    grating = GratingSpec.from_bench(sc["bench"])
    sensor = SensorParams.from_section(sc["instruments"]["ccd"])
    camera = sensor.camera(sc["bench"]["ccd_position"])
    W, H = camera.width_px, camera.height_px
    e_m, th0 = sc["errors"]["eccentricity"], sc["errors"]["theta0"]
    t = math.radians(37.0)
    a = math.pi / 2 - th0 + t
    pose = BodyPose(pos=np.array([e_m * math.cos(a), e_m * math.sin(a), 0.0]), R=rz(t))
    scene = build_scene(pose, grating, camera)
    ref_xy = (float(camera.reference_px[0]), float(camera.reference_px[1]))
    exact = coverage_image(scene.polygons, W, H, camera.reference_px)
    out: dict[str, object] = {"frame_px": [W, H], "lines": len(scene.polygons), "k": args.k}

    work = workspace(W, H)   # kept from frame to frame, as the GL context keeps its buffers
    floor_cov = area_coverage(scene.polygons, W, H, ref_xy, work)
    out["floor_render_s"], out["floor_render_cpu_s"] = timed(
        lambda: area_coverage(scene.polygons, W, H, ref_xy, work), args.repeat)
    out["floor_end_error_px"] = end_error(floor_cov, exact, scene.end_mid_px)
    out["floor_max_pixel_error"] = float(np.max(np.abs(floor_cov - exact)))
    fp_cov = cv_coverage(scene.polygons, W, H, ref_xy, args.k)
    out["fillpoly_render_s"], out["fillpoly_render_cpu_s"] = timed(
        lambda: cv_coverage(scene.polygons, W, H, ref_xy, args.k), args.repeat)
    out["fillpoly_end_error_px"] = end_error(fp_cov, exact, scene.end_mid_px)

    vign = np.ones((H, W), np.float32)
    max_dn = int(sensor.max_dn)
    out["floor_sensor_s"], out["floor_sensor_cpu_s"] = timed(
        lambda: cv_sensor(floor_cov, 1.2, vign, max_dn, sensor.dtype), args.repeat)

    with Renderer("auto") as r:
        cov, _, used = r.coverage(pose, grating, camera)
        out["twin_backend"] = used
        out["twin_render_s"], out["twin_render_cpu_s"] = timed(lambda: r.coverage(pose, grating, camera), args.repeat)
        out["twin_end_error_px"] = end_error(np.asarray(cov, np.float64), exact, scene.end_mid_px)
        irr, _, _ = r.irradiance(pose, grating, camera)
    out["twin_sensor_s"], out["twin_sensor_cpu_s"] = timed(
        lambda: apply_sensor(irr.copy(), sensor, np.random.default_rng(0), pixel_m=camera.true_pixel_m), args.repeat)

    fr, tr = float(out["floor_render_s"]), float(out["twin_render_s"])  # type: ignore[arg-type]
    frc, trc = float(out["floor_render_cpu_s"]), float(out["twin_render_cpu_s"])  # type: ignore[arg-type]
    fpr, fpc = float(out["fillpoly_render_s"]), float(out["fillpoly_render_cpu_s"])  # type: ignore[arg-type]
    fs, ts = float(out["floor_sensor_s"]), float(out["twin_sensor_s"])  # type: ignore[arg-type]
    fsc, tsc = float(out["floor_sensor_cpu_s"]), float(out["twin_sensor_cpu_s"])  # type: ignore[arg-type]
    print(f"frame {W}×{H} px, {len(scene.polygons)} lines in view; wall / CPU ms, ratio to the floor wall / CPU")
    print(f"floor render  (exact area accumulation, numpy)     {fr * 1e3:6.1f} / {frc * 1e3:6.1f}            "
          f"line-end error ≤ {out['floor_end_error_px']:.2g} px")
    print(f"twin render   ({used:9s})                         {tr * 1e3:6.1f} / {trc * 1e3:6.1f}  "
          f"×{tr / fr:4.1f} / ×{trc / frc:4.1f}  line-end error ≤ {out['twin_end_error_px']:.4f} px")
    print(f"(fillPoly {args.k}×{args.k} + INTER_AREA, lower quality) {fpr * 1e3:6.1f} / {fpc * 1e3:6.1f}            "
          f"line-end error ≤ {out['fillpoly_end_error_px']:.4f} px")
    print(f"floor sensor  (GaussianBlur, multiply, noise, cast) {fs * 1e3:6.1f} / {fsc * 1e3:6.1f}")
    print(f"twin sensor   (twin/render/sensor.py apply_sensor)  {ts * 1e3:6.1f} / {tsc * 1e3:6.1f}  "
          f"×{ts / fs:4.1f} / ×{tsc / fsc:4.1f}")
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
