"""Speed and accuracy of the CCD renderer (Jia 2019 sec. 4.2 images, 2048×1536 px).

Prints, and writes into docs/benchmarks.md under "## CCD rendering":

- a bare pyrender frame (stock ``OffscreenRenderer.render``: one 4× MSAA pass, RGB + depth read),
  the reference of every ratio;
- the GL coverage renderer per supersampling factor k (jitter 1), per jitter n (k = 1), and the
  default configuration (k = 1, n = 2, end band): time, ratio, and the line-end error against the
  exact analytic renderer (max over the lines in view, 50 % crossing of row profiles, and the area
  method) — so the speed of each setting is shown next to the accuracy it buys;
- the analytic renderer, the sensor model, and the full 60-image sweep (every 6°, Jia's
  eccentricity 7.1 µm at θ0 = 192.08°) with each backend; the sweep's images are then fed to the
  analysis (``benchtwin.analysis.eccentricity``) as an end-to-end check.

Usage: ``.venv/bin/python benchmarks/render_bench.py [--frames 60] [--no-write] [--no-analysis]``.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from benchtwin.twin.render import gl

gl.configure()

from benchtwin.twin.pose import BodyPose  # noqa: E402
from benchtwin.twin.render import GratingSpec, Renderer, SensorParams  # noqa: E402
from benchtwin.twin.render.analytic import coverage_image  # noqa: E402
from benchtwin.twin.render.grating import build_scene, to_trimesh  # noqa: E402
from benchtwin.twin.render.pyrender_backend import CoverageSampling, GlCoverageRenderer  # noqa: E402
from benchtwin.twin.render.sensor import apply_sensor  # noqa: E402
from benchtwin.twin.scenario import load_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
SECTION = "## CCD rendering"


def rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def disk_pose(t_rad: float, e_m: float, theta0_rad: float) -> BodyPose:
    """docs/conventions.md: the disk centre sits at e, lab polar angle 90° − θ0 + t."""
    a = math.pi / 2 - theta0_rad + t_rad
    return BodyPose(pos=np.array([e_m * math.cos(a), e_m * math.sin(a), 0.0]), R=rz(t_rad))


def timeit(fn, repeat: int) -> float:
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def end_errors(cov: np.ndarray, ref: np.ndarray, ends: np.ndarray) -> tuple[float, float]:
    """Max |Δ| over lines of the end position by 50 % crossing and by area (rows around the end)."""
    h, w = cov.shape
    dc, da = [], []
    for xm, ym in ends:
        yc, x0 = int(round(ym)), int(math.floor(xm)) - 8
        if not (6 <= yc < h - 6 and 0 <= x0 and x0 + 17 < w):
            continue
        for y in range(yc - 4, yc + 5):
            vals = []
            for img in (cov, ref):
                seg = img[y, x0:x0 + 17]
                j = np.flatnonzero((seg[:-1] >= 0.5) & (seg[1:] < 0.5))[0]
                vals.append((x0 + j + (seg[j] - 0.5) / (seg[j] - seg[j + 1]), x0 - 0.5 + seg.sum()))
            dc.append(vals[0][0] - vals[1][0])
            da.append(vals[0][1] - vals[1][1])
    return float(np.max(np.abs(dc))), float(np.max(np.abs(da)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--no-analysis", action="store_true")
    args = ap.parse_args(argv)

    sc = load_scenario()
    grating = GratingSpec.from_bench(sc["bench"])
    sensor = SensorParams.from_section(sc["instruments"]["ccd"])
    camera = sensor.camera(sc["bench"]["ccd_position"])
    W, H = camera.width_px, camera.height_px
    e_m, th0 = sc["errors"]["eccentricity"], sc["errors"]["theta0"]
    pose = disk_pose(math.radians(37.0), e_m, th0)
    scene = build_scene(pose, grating, camera)
    ref_cov = coverage_image(scene.polygons, W, H, camera.reference_px)
    rows: list[tuple[str, float, str]] = []  # (case, s/frame, accuracy text)

    pr = gl.pyrender()
    # ---- bare pyrender frame: stock render of the same line mesh, one MSAA pass
    r = pr.OffscreenRenderer(W, H)
    s = pr.Scene(bg_color=[1.0, 1.0, 1.0, 1.0])
    tm = to_trimesh(scene.polygons, offset_px=(0.5, 0.5))
    tm.visual.vertex_colors = np.tile(np.array([0, 0, 0, 255], np.uint8), (len(tm.vertices), 1))
    s.add(pr.Mesh.from_trimesh(tm, smooth=False))
    s.add(pr.OrthographicCamera(xmag=W / 2, ymag=H / 2, znear=0.5, zfar=10.0),
          pose=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 2.0], [0, 0, 0, 1]]))
    r.render(s, flags=pr.RenderFlags.FLAT)
    t_bare = timeit(lambda: r.render(s, flags=pr.RenderFlags.FLAT), args.repeat)
    r.delete()
    rows.append(("bare pyrender frame (1 pass 4× MSAA, stock RGB+depth readback)", t_bare, "¼-px steps"))
    print(f"{rows[-1][0]:55s} {t_bare:7.3f} s", flush=True)

    def gl_case(label: str, k: int, n: int, band: bool, nb: int = 2) -> None:
        sampling = CoverageSampling(supersample=k, jitter=n, end_band=band, band_jitter=nb)
        with GlCoverageRenderer(W, H, sampling) as g:
            ends_x = scene.end_x_px(camera.reference_px)
            cov = g.coverage(scene.polygons, ends_x)
            t = timeit(lambda: g.coverage(scene.polygons, ends_x), args.repeat)
        ec, ea = end_errors(cov, ref_cov, scene.end_mid_px)
        body = float(np.abs(cov - ref_cov).max())
        rows.append((label, t, f"line ends: crossing ≤ {ec:.4f} px, area ≤ {ea:.4f} px; max pixel Δcoverage {body:.3f}"))
        print(f"{label:55s} {t:7.3f} s  ×{t / t_bare:5.1f}  {rows[-1][2]}", flush=True)

    for k in (1, 2, 3):
        gl_case(f"GL supersample k={k} (jitter 1, no end band)", k, 1, False)
    for n in (2, 4, 8):
        gl_case(f"GL jitter n={n} (k=1, no end band)", 1, n, False)
    gl_case("GL default: k=1, jitter 2, end band (2 passes)", 1, 2, True)

    t_an = timeit(lambda: coverage_image(scene.polygons, W, H, camera.reference_px), args.repeat)
    rows.append(("analytic exact coverage (numpy)", t_an, "exact (reference)"))
    irr = grating.glass_transmission + (grating.chrome_transmission - grating.glass_transmission) * ref_cov
    rng = np.random.default_rng(1)
    t_sensor = timeit(lambda: apply_sensor(irr, sensor, rng, camera.true_pixel_m), args.repeat)
    rows.append(("sensor model (dust, blur, vignetting, noise, 8 bit)", t_sensor, ""))
    t_scene = timeit(lambda: build_scene(pose, grating, camera), args.repeat)
    rows.append(("scene geometry (lines in view)", t_scene, f"{len(scene.polygons)} lines"))
    for label, t, acc in rows[-3:]:
        print(f"{label:55s} {t:7.3f} s  ×{t / t_bare:5.1f}  {acc}")

    # ---- sweeps
    thetas = np.arange(args.frames) * (360.0 / args.frames)
    sweeps = {}
    for backend in ("pyrender", "analytic"):
        rng = np.random.default_rng(sc.seed)
        images = []
        with Renderer(backend=backend) as rend:
            rend.render(disk_pose(0.0, e_m, th0), grating, camera, sensor, np.random.default_rng(0))  # context, shaders
            t0 = time.perf_counter()
            per_frame = []
            for th in thetas:
                t1 = time.perf_counter()
                images.append(rend.render(disk_pose(math.radians(th), e_m, th0), grating, camera, sensor, rng).image)
                per_frame.append(time.perf_counter() - t1)
            dt = time.perf_counter() - t0
        sweeps[backend] = (dt, images, statistics.median(per_frame))
        print(f"sweep {args.frames} frames, {backend:9s}: {dt:6.1f} s ({dt / args.frames:.3f} s/frame, "
              f"median {statistics.median(per_frame):.3f})", flush=True)

    # full frame vs the bare rasteriser at the same supersampling (the default's GL passes and
    # nothing else), measured INTERLEAVED so that other jobs on the machine slow both alike
    t_full_l, t_bare_l = [], []
    with Renderer(backend="pyrender") as rend:
        rend.render(pose, grating, camera, sensor, np.random.default_rng(0))
        g = rend._gl
        passes = g.n + g.band_jitter
        rng = np.random.default_rng(2)
        for i in range(4 * args.repeat):
            p_i = disk_pose(math.radians(6.0 * i), e_m, th0)
            t0 = time.perf_counter()
            rend.render(p_i, grating, camera, sensor, rng)
            t_full_l.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for _ in range(passes):
                g._r.render(g._scene, flags=pr.RenderFlags.FLAT)
            t_bare_l.append(time.perf_counter() - t0)
    t_raster = statistics.median(t_bare_l)
    t_pass = t_raster / passes
    per_inter = statistics.median(t_full_l)

    analysis = ""
    if not args.no_analysis:
        try:
            from benchtwin.analysis.eccentricity import CcdSweep, eccentricity_from_images

            for backend, (_, images, _m) in sweeps.items():
                t0 = time.perf_counter()
                res = eccentricity_from_images(images, thetas, CcdSweep(um_per_px=camera.pixel_pitch_m * 1e6,
                                                                        reference_px=camera.reference_px))
                ta = time.perf_counter() - t0
                e_um = res.get("e_um", res.get("e"))
                th_deg = res.get("theta0_deg", res.get("theta0"))
                line = (f"analysis of the {backend} sweep: e = {float(e_um):.3f} µm, θ0 = {float(th_deg):.2f}° "
                        f"(truth 7.100 µm, 192.08°; {ta:.1f} s)")
                print(line)
                analysis += f"- {line}\n"
        except Exception as exc:  # the analysis belongs to another module: report, don't fail
            analysis = f"- analysis not run: {type(exc).__name__}: {exc}\n"
            print(analysis.strip())

    dt_gl = sweeps["pyrender"][0]
    per = sweeps["pyrender"][2]  # median s/frame (robust to other jobs on the machine)
    verdict_30 = "met" if dt_gl * 60 / args.frames < 30 else "NOT met"
    verdict_2x = "met" if per_inter < 2 * t_raster else "NOT met"
    summary = (f"- full sweep, pyrender default: {dt_gl:.1f} s for {args.frames} frames (median {per:.3f} s/frame); "
               f"target < 30 s for 60: **{verdict_30}**.\n"
               f"- bare rasteriser at the needed supersampling (the default's {passes} GL passes, "
               f"{t_pass:.3f} s each): {t_raster:.3f} s/frame vs full frame {per_inter:.3f} s (interleaved medians): "
               f"full / bare = {per_inter / t_raster:.2f} (vs one stock pyrender frame: {per_inter / t_bare:.2f}); "
               f"target ≤ 2×: **{verdict_2x}**.\n"
               f"- analytic sweep: {sweeps['analytic'][0]:.1f} s ({sweeps['analytic'][0] / args.frames:.3f} s/frame).\n")
    print(summary)

    if not args.no_write:
        import pyrender as _p

        table = "\n".join(f"| {label} | {t * 1000:.0f} | {t / t_bare:.1f} | {acc} |" for label, t, acc in rows)
        cpu = os.cpu_count()
        text = f"""{SECTION}

`benchmarks/render_bench.py` — CCD microscope frames of the grating edge (Jia 2019 sec. 4.2),
2048×1536 px, {len(scene.polygons)} lines in view, jia2019 scenario. Median of {args.repeat} runs.
Machine: {cpu} cores ({platform.machine()}), Python {platform.python_version()}, pyrender {_p.__version__},
GL: Mesa llvmpipe via {os.environ.get('PYOPENGL_PLATFORM')} (no GPU). Other jobs may share the CPU.
"GL" rows: the coverage renderer (`twin/render/pyrender_backend.py`: single-channel R8 4× MSAA
buffer, no depth, one-channel readback), coverage only; "× bare frame" is against one stock
pyrender frame of the same mesh. Accuracy: largest per-row difference of the line-end position
from the exact analytic coverage, over the {len(scene.polygons)} lines, rows ±4 around each end.

| case | ms/frame | × bare frame | accuracy vs exact coverage |
| --- | --- | --- | --- |
{table}

{summary}{analysis}
What bounds it: llvmpipe fills every 4× MSAA sample of the 3 Mpx framebuffer on the CPU (clear,
raster of the ~half-covered frame, resolve, read): {t_pass * 1000:.0f} ms a pass whatever the
geometry ({len(scene.polygons)} lines are nothing). Sub-pixel accuracy multiplies passes: k× supersampling costs k²
passes' worth of pixels for 4k sample positions per axis, jitter n costs n passes for 4n; the end
band (an anisotropic pass, {W}/band-width× in x over the ~30 columns holding the line ends) brings
the line ends, which Jia's circle fit measures, to ≤ 0.005 px for its 2 passes, where uniform
supersampling would need k ≈ 25. The rest of a frame (sensor model ≈ {t_sensor * 1000:.0f} ms: one
3 Mpx Gaussian draw and a dozen memory-bound array passes; mesh, accumulation) is the gap between
"full frame" and "bare". The exact numpy renderer is faster than any GL setting of comparable
accuracy, because it only does real work at the ~2 % of pixels an edge crosses; GL stays the
default backend (per design) and the analytic one is its cross-check and fallback.
"""
        old = DOC.read_text() if DOC.exists() else "# Benchmarks\n"
        pat = re.compile(rf"^{re.escape(SECTION)}\n.*?(?=^## |\Z)", re.S | re.M)
        new = pat.sub(lambda _m: text.rstrip() + "\n\n", old) if pat.search(old) else old.rstrip() + "\n\n" + text
        DOC.write_text(new.rstrip() + "\n")
        print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
