"""A rendered view of the bench model: MuJoCo's own offscreen renderer (``mujoco.Renderer``,
``MUJOCO_GL=egl``: Mesa's software EGL, no screen, no GPU), with the instruments marked.

The picture shows the bodies of the twin's MuJoCo model (``twin.physics.Bench``: shaft, bearing
housings, grating disk, test spheres, polygon) posed at θ = 0 by the bench's own static solve. The
instruments are not bodies of the model (they read the posed bodies' geometry, twin/instruments/),
so they are drawn as markers added to MuJoCo's scene (``mjv_initGeom``) at the places
docs/conventions.md gives them — reading heads on the disk at the optical radius (head 1 on +Y,
further heads at ``heads_deg`` counter-clockwise), the probes along +Y (and +X) of each sphere,
the autocollimator on +X at the polygon's height, the CCD microscope above the scale edge at
``ccd_position`` — and labelled by projecting those points with the renderer's camera.

The render (image + label points) is cached per bench geometry (``render_bench_cached``): building
the twin's ``Bench`` (importing MuJoCo, the static solve) and the offscreen render cost ~2 s of a
``benchtwin analyze`` that otherwise never touches the twin, for a picture that depends only on
the scenario and the code. The cache lives in ``$BENCHTWIN_CACHE/bench_view`` (default
``~/.cache/benchtwin/bench_view``, the folder benchtwin's other caches use), one ``<key>.npz`` per
geometry (the ``CACHE_MAX_ENTRIES`` most recently used are kept), the key a SHA-256 of the scenario's full content, the picture size, the MuJoCo version
and the sources the picture is made of (this module, twin/*.py, models/*). A file is written under
a unique temporary name and renamed into place (``benchtwin.fsio.atomic_write_bytes``), so concurrent
runs never read a half-written picture; an unreadable or foreign file is re-rendered and replaced.
``BENCHTWIN_CACHE=none`` turns the cache off; a cache folder that cannot be written only costs the
re-render.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.fsio import OutputError, atomic_write_bytes

WIDTH, HEIGHT = 1000, 760


def _add_geom(scene: Any, gtype: Any, size: Any, pos: Any, rgba: Any, mat: Any = None) -> None:
    import mujoco

    if scene.ngeom >= scene.maxgeom:
        return
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(g, gtype, np.asarray(size, dtype=float), np.asarray(pos, dtype=float),
                        np.eye(3).ravel() if mat is None else np.asarray(mat, dtype=float).ravel(),
                        np.asarray(rgba, dtype=np.float32))
    scene.ngeom += 1


def _add_rod(scene: Any, a: Any, b: Any, radius: float, rgba: Any) -> None:
    import mujoco

    if scene.ngeom >= scene.maxgeom:
        return
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.eye(3).ravel(),
                        np.asarray(rgba, dtype=np.float32))
    mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, np.asarray(a, float), np.asarray(b, float))
    scene.ngeom += 1


def instrument_points(sc: Any, bench: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """name -> (marker position, point it looks at), lab frame, m (docs/conventions.md)."""
    b = sc["bench"]
    d = bench.data
    bid = {n: bench.model.body(n).id for n in ("disk", "sphere_top", "sphere_bottom", "polygon")}
    disk, top, bot, pol = (np.array(d.xpos[bid[n]]) for n in ("disk", "sphere_top", "sphere_bottom", "polygon"))
    r = float(b["optical_radius"])
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    heads = [float(h) for h in b.get("heads", [0.0])] or [0.0]
    for k, h in enumerate(heads):
        a = math.pi / 2 + h
        p = disk + np.array([r * math.cos(a), r * math.sin(a), 0.0])
        out[f"head {k + 1}" if len(heads) > 1 else "reading head"] = (p + np.array([0, 0, 0.004]), p)
    rs = 0.006
    for name, c in (("probe top", top), ("probe bottom", bot)):
        out[f"{name} (Y)"] = (c + np.array([0.0, rs + 0.025, 0.0]), c + np.array([0.0, rs, 0.0]))
        out[f"{name} (X)"] = (c + np.array([-(rs + 0.025), 0.0, 0.0]), c + np.array([-rs, 0.0, 0.0]))
    out["autocollimator"] = (pol + np.array([0.09, 0.0, 0.0]), pol + np.array([0.02, 0.0, 0.0]))
    re = float(b.get("scale_edge_radius", r + 0.0005))
    ccd_az = math.pi / 2 + float(b.get("ccd_position", math.pi))  # from head 1 (on +Y), CCW
    e = disk + np.array([re * math.cos(ccd_az), re * math.sin(ccd_az), 0.0])
    out["CCD microscope"] = (e + np.array([0.0, 0.0, 0.035]), e)
    return out


def _egl_display_initialised() -> None:
    """Re-initialise MuJoCo's EGL display if a pyrender renderer of this process terminated it.

    EGL gives every caller in a process the same display for a device; ``mujoco.egl`` initialises
    it once and keeps it (``EGL_DISPLAY``), while pyrender, when its renderer is deleted, calls
    ``eglTerminate`` on it (pyrender/platforms/egl.py ``delete_context``). A bench view drawn after
    a CCD renderer of the same process was closed (the serial frame path, a test session) then
    failed with EGL_NOT_INITIALIZED. ``eglInitialize`` on an initialised display changes nothing
    (EGL 1.5 sec. 3.2), and re-initialises a terminated one."""
    if os.environ.get("MUJOCO_GL", "").strip().lower() != "egl":
        return
    import sys

    egl = sys.modules.get("mujoco.egl")      # imported by MuJoCo's first EGL context, if any
    display = getattr(egl, "EGL_DISPLAY", None)
    if egl is not None and display is not None:
        egl.EGL.eglInitialize(display, None, None)


def render_bench(sc: Any, width: int = WIDTH, height: int = HEIGHT) -> tuple[np.ndarray, dict[str, tuple[float, float]]]:
    """(RGB image, {label: (u, v) px}) of the bench of scenario ``sc`` posed at θ = 0."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    from benchtwin.twin.physics import Bench

    bench = Bench(sc)
    bench.pose_at(0.0)
    m, d = bench.model, bench.data
    # the shaft drawn translucent: the test spheres sit in its envelope (a render-only change of
    # this Bench's model, which is used for nothing else)
    sid = m.geom("shaft").id
    m.geom_rgba[sid, 3] = 0.35
    m.vis.global_.offwidth = max(m.vis.global_.offwidth, width)
    m.vis.global_.offheight = max(m.vis.global_.offheight, height)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    z = [float(d.xpos[m.body(n).id][2]) for n in ("sphere_top", "polygon")]
    cam.lookat[:] = [0.0, 0.0, 0.5 * (z[0] + z[1])]
    cam.distance = 1.25 * (z[0] - z[1]) + 0.12
    cam.azimuth, cam.elevation = 35.0, -18.0
    opt = mujoco.MjvOption()
    for gi in range(len(opt.geomgroup)):
        opt.geomgroup[gi] = 1
    _egl_display_initialised()
    with mujoco.Renderer(m, height=height, width=width) as renderer:
        renderer.update_scene(d, camera=cam, scene_option=opt)
        scene = renderer.scene
        marks = instrument_points(sc, bench)
        colours = {"head": (0.1, 0.6, 0.1, 1), "probe": (0.85, 0.45, 0.0, 1), "autocollimator": (0.2, 0.3, 0.9, 1),
                   "CCD": (0.7, 0.1, 0.6, 1), "reading": (0.1, 0.6, 0.1, 1)}
        for name, (p, q) in marks.items():
            rgba = colours[next(k for k in colours if name.startswith(k))]
            if name.startswith(("head", "reading")):
                _add_geom(scene, mujoco.mjtGeom.mjGEOM_BOX, (0.003, 0.003, 0.003), p, rgba)
            elif name.startswith("autocollimator"):
                _add_rod(scene, p, q, 0.004, (0.6, 0.7, 1.0, 0.35))  # the beam
                _add_geom(scene, mujoco.mjtGeom.mjGEOM_BOX, (0.02, 0.012, 0.012), p, rgba)
            else:
                _add_rod(scene, p, q, 0.0015 if name.startswith("probe") else 0.004, rgba)
        img = renderer.render().copy()
    # project with the free camera's own geometry (MuJoCo: forward from azimuth/elevation, the
    # camera at lookat − distance·forward, vertical field of view vis.global.fovy)
    az, el = math.radians(cam.azimuth), math.radians(cam.elevation)
    fwd = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    up = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)])
    right = np.cross(fwd, up)
    pos = np.array(cam.lookat) - cam.distance * fwd
    f = (height / 2) / math.tan(math.radians(m.vis.global_.fovy) / 2)

    def project(p: np.ndarray) -> tuple[float, float] | None:
        v = np.asarray(p, dtype=float) - pos
        zc = float(v @ fwd)
        if zc <= 0:
            return None
        return width / 2 + f * float(v @ right) / zc, height / 2 - f * float(v @ up) / zc

    labels: dict[str, tuple[float, float]] = {}
    n_heads = sum(1 for n in marks if n.startswith("head "))
    for name, (p, _) in marks.items():
        if name.endswith("(X)"):
            continue  # drawn, not labelled: they sit beside the Y probes
        if name.startswith("head ") and n_heads > 3:
            if name != "head 1":
                continue  # many heads: one label, at head 1
            name = f"head 1 (of {n_heads} reading heads)"
        uv = project(p)
        if uv is not None:
            labels[name.replace(" (Y)", "s (Y, X)")] = uv
    bodies = {"shaft": d.xpos[m.body("shaft").id] + np.array([0.0, 0.0, -0.03]), "grating disk": d.xpos[m.body("disk").id],
              "sphere top": d.xpos[m.body("sphere_top").id], "sphere bottom": d.xpos[m.body("sphere_bottom").id],
              "polygon": d.xpos[m.body("polygon").id]}
    for g in ("bearing_top_housing", "bearing_bottom_housing"):
        bodies[g.replace("_housing", "").replace("_", " ")] = d.geom_xpos[m.geom(g).id]
    for name, p in bodies.items():
        uv = project(p)
        if uv is not None:
            labels["@" + name] = uv
    # the model has no skybox: the empty background renders black; show it light
    bg = np.all(img == 0, axis=2)
    img[bg] = 238
    return img, labels


#: bump when the cached file's layout changes (part of the key)
_CACHE_FORMAT = 1
#: pictures kept (≈ 40 kB each, compressed): the most recently used
CACHE_MAX_ENTRIES = 64


def bench_view_cache_dir() -> Path | None:
    """Where rendered bench views are kept: $BENCHTWIN_CACHE/bench_view (default
    ~/.cache/benchtwin/bench_view); None when BENCHTWIN_CACHE is ``none`` (cache off)."""
    root = os.environ.get("BENCHTWIN_CACHE")
    if root is not None and root.strip().lower() in ("none", "off", "0"):
        return None
    return Path(root or Path.home() / ".cache" / "benchtwin") / "bench_view"


def bench_view_key(sc: Any, width: int = WIDTH, height: int = HEIGHT) -> str:
    """SHA-256 (hex) of everything the picture depends on: the scenario's full validated content, the
    size, the MuJoCo version and the sources of the model and of this picture (a few ms)."""
    from importlib.metadata import PackageNotFoundError, version

    from benchtwin.twin.code_digest import update_with_sources

    h = hashlib.sha256()
    try:
        mj = version("mujoco")
    except PackageNotFoundError:  # pragma: no cover - the twin needs MuJoCo
        mj = "?"
    h.update(json.dumps({"format": _CACHE_FORMAT, "size": [int(width), int(height)], "mujoco": mj,
                         "scenario": sc.to_dict()}, sort_keys=True, default=repr).encode())
    h.update(Path(__file__).read_bytes())
    update_with_sources(h, (("benchtwin.twin", "*.py"), ("benchtwin.models", "*")))
    return h.hexdigest()


def render_bench_cached(sc: Any, width: int = WIDTH, height: int = HEIGHT
                        ) -> tuple[np.ndarray, dict[str, tuple[float, float]]]:
    """:func:`render_bench`, read from the cache when this geometry was rendered before (module
    docstring: where, key, atomic writes)."""
    folder = bench_view_cache_dir()
    if folder is None:
        return render_bench(sc, width, height)
    key = bench_view_key(sc, width, height)
    path = folder / f"{key}.npz"
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) == key:
                img = np.array(z["image"])
                labels = {str(k): (float(u), float(v)) for k, (u, v) in json.loads(str(z["labels"])).items()}
                if img.shape == (height, width, 3) and img.dtype == np.uint8:
                    os.utime(path)  # recently used: the last to be evicted
                    return img, labels
    except (OSError, ValueError, KeyError, TypeError, json.JSONDecodeError):
        pass  # absent, half-foreign or damaged: rendered afresh and replaced
    img, labels = render_bench(sc, width, height)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez_compressed(buf, key=np.array(key), image=img,
                            labels=np.array(json.dumps({k: [float(u), float(v)] for k, (u, v) in labels.items()})))
        atomic_write_bytes(path, buf.getvalue(), fsync=False)  # a cache: a lost entry is re-rendered
        _evict(folder, CACHE_MAX_ENTRIES)
    except (OSError, OutputError):  # OutputError: fsio's DiskFullError
        pass  # a read-only or full cache folder costs the re-render next time, nothing else
    return img, labels


def _evict(folder: Path, keep: int) -> None:
    """Remove all but the ``keep`` most recently used pictures (a design study draws one geometry per
    point; the folder must not grow with every study). A file another process removes or reads
    meanwhile is harmless: a reader holding it open still reads it, a missing one is re-rendered."""
    files = []
    for f in folder.glob("*.npz"):
        try:
            files.append((f.stat().st_mtime, f))
        except OSError:
            continue
    for _, f in sorted(files, reverse=True)[keep:]:
        f.unlink(missing_ok=True)


def fig_bench(sc: Any, what: str | None = None) -> Any:
    """The rendered bench with labels (a matplotlib figure for the report; the render from the
    cache when this geometry was drawn before)."""
    from matplotlib.figure import Figure

    img, labels = render_bench_cached(sc)
    H, W = img.shape[:2]
    fig = Figure(figsize=(10, 10 * H / W + 0.35))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=1.0 - 0.35 / (10 * H / W + 0.35))  # the title's 0.35 in
    ax.imshow(img)
    left = sorted((n for n in labels if n.startswith("@")), key=lambda n: labels[n][1])
    right = sorted((n for n in labels if not n.startswith("@")), key=lambda n: labels[n][1])
    for names, x_text in ((left, 0.04 * W), (right, 0.80 * W)):
        ys = np.linspace(0.12 * H, 0.9 * H, max(len(names), 1))
        for name, y_text in zip(names, ys):
            u, v = labels[name]
            body = name.startswith("@")
            text = name[1:] if body else name
            ax.annotate(text, (u, v), xytext=(x_text, y_text), fontsize=8,
                        color="#222" if body else "#0b3d91",
                        arrowprops={"arrowstyle": "-", "color": "#555" if body else "#0b3d91", "lw": 0.7},
                        bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.85})
    ax.set_axis_off()
    ax.set_title(f"The bench model of {what or 'scenario ' + sc.name} (MuJoCo offscreen render, θ = 0); instruments marked",
                 fontsize=10)
    return fig


def bench_preface(sc: Any, what: str | None = None) -> list:
    """[(figure, caption)] for the report's opening: the rendered bench, or nothing when no OpenGL
    context can be had here (the report then simply starts with its summary)."""
    try:
        fig = fig_bench(sc, what)
    except Exception as exc:  # noqa: BLE001 - a missing EGL/OSMesa must not cost the analysis
        import warnings

        warnings.warn(f"bench view not rendered: {type(exc).__name__}: {exc}", stacklevel=2)
        return []
    return [(fig, "The bench model (MuJoCo's offscreen renderer): shaft, bearings, grating disk, test spheres and "
                  "polygon posed by the twin at θ = 0, with the reading heads, probes, autocollimator and CCD "
                  "microscope marked where they read")]


def scenario_from_manifest(manifest: dict) -> Any:
    """A nominal twin scenario with a dataset's declared bench geometry (optical radius, scale edge,
    L1, L2, heads, polygon faces, grating, CCD azimuth) — for the picture only: every other part
    (bearing positions, masses, errors) keeps the embedded default, and nothing of it is analysed."""
    from benchtwin.twin.scenario import load_scenario

    b = manifest.get("bench") or {}
    over: dict[str, Any] = {}
    for key, skey, unit in (("optical_radius_mm", "bench.optical_radius", "mm"), ("scale_edge_radius_mm",
                            "bench.scale_edge_radius", "mm"), ("L1_mm", "bench.L1", "mm"), ("L2_mm", "bench.L2", "mm"),
                            ("grating_period_um", "bench.grating_period", "um")):
        if isinstance(b.get(key), (int, float)):
            over[skey] = f"{float(b[key])!r} {unit}"
    for key in ("polygon_faces", "encoder_lines"):
        if isinstance(b.get(key), int):
            over[f"bench.{key}"] = int(b[key])
    if b.get("heads_deg"):
        over["bench.heads"] = [f"{float(h)!r} deg" for h in b["heads_deg"]]
    ccd = manifest.get("ccd") or {}
    if isinstance(ccd.get("position_deg"), (int, float)):
        over["bench.ccd_position"] = f"{float(ccd['position_deg'])!r} deg"
    return load_scenario().with_overrides(over)


def bench_preface_for_dataset(dataset: Any) -> list:
    """The opening picture for ``analyze`` / ``close-loop``: the bench model with the dataset's
    declared geometry (``scenario_from_manifest``), or nothing when that cannot be built or drawn."""
    from pathlib import Path

    from benchtwin.schema import loads_json, read_input_text

    try:  # the one reader: a manifest that is a FIFO is refused here, not opened (analyze names it)
        p = Path(dataset) / "manifest.json"
        man = loads_json(read_input_text(p, max_bytes=1024 * 1024, what="manifest"), str(p))
        sc = scenario_from_manifest(man)
    except Exception:  # noqa: BLE001 - a missing or bad manifest: the analysis reports it (exit 2), no picture
        return []
    pre = bench_preface(sc, f"dataset {Path(dataset).name} (declared geometry)")
    return [(fig, cap + " — a nominal model with the dataset's declared geometry (L1, L2, r, heads, faces); the "
             "other parts are the twin's defaults") for fig, cap in pre]
