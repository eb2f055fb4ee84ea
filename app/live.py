"""A live view of a long run: a self-refreshing HTML page beside the dataset (issue 20).

A Hsieh-type acquisition takes hours (Hsieh et al. 2022: 6.8 h of bench time); the page shows
what a metrologist walking past the bench wants to see: the procedure step, progress and an ETA,
the last reading of each instrument, and a running plot of what is known so far — during the
polygon runs the shift-angle α estimated from the start-face runs completed so far (Hsieh eq. 3,
:meth:`LiveView.alpha_so_far`), before them the probes' readings over each revolution of the
radial-motion run (Jia sec. 4.1) or the self-calibration heads' difference.

The page is an observer: ``on_step`` / ``on_row`` follow the signatures of
``benchtwin.hw.acquisition.runner.Runner`` (the acquire and simulate commands pass them through),
so the run itself never depends on it. It is cheap: O(1) state (the last points of a bounded
number of curves), rendered at most once per ``min_interval_s`` of wall time (and at the end), and
written atomically (``benchtwin.fsio.atomic_write_text``: a browser never reads half a page). The page
reloads itself every ``refresh_s`` seconds (``<meta http-equiv="refresh">``; no script, no server:
it opens from the file system). Every number shown carries its unit.
"""

from __future__ import annotations

import html
import math
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from benchtwin.fsio import atomic_write_text

__all__ = ["LiveView"]

MAX_CURVES = 12  # completed runs kept in the running plot
MAX_POINTS = 720  # points per curve (a 0.5° radial sweep)


def _fmt_duration(s: float) -> str:
    if not math.isfinite(s) or s < 0:
        return "–"
    s = int(round(s))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h} h {m:02d} min" if h else (f"{m} min {sec:02d} s" if m else f"{sec} s")


def _reading_text(r: Any) -> str:
    """One instrument's reading as text with its units (the keys carry them: value_um, x_arcsec...)."""
    if not isinstance(r, Mapping):
        return html.escape(str(r))
    parts = []
    for k, v in r.items():
        if k in ("status", "t_s"):
            continue
        if isinstance(v, (list, tuple)):
            v = ", ".join(f"{x:.6g}" if isinstance(x, float) else str(x) for x in v[:12]) + (" …" if len(v) > 12 else "")
        elif isinstance(v, float):
            v = f"{v:.6g}"
        parts.append(f"{html.escape(str(k))} = {html.escape(str(v))}")
    st = r.get("status")
    if st and st != "ok":
        parts.append(f"status {html.escape(str(st))}")
    return "; ".join(parts)


#: per procedure: (instrument, key in its reading, y label) the running plot follows, x = encoder angle
_PLOT = {
    "polygon": ("autocollimator", "x_arcsec", "autocollimator x (″) at each face"),
    "radial_motion": ("probe_top", "value_um", "top probe (µm)"),
    "selfcal": ("encoder", "heads_deg", "head 2 − head 1 (″)"),
}


class LiveView:
    """Collects the run's progress and writes ``path`` (an HTML page) now and then."""

    def __init__(self, path: str | Path, title: str, n_steps: int, *, min_interval_s: float = 1.0,
                 refresh_s: float = 2.0, clock: Callable[[], float] = time.monotonic):
        self.path = Path(path)
        self.title = title
        self.n_steps = int(n_steps)
        self.min_interval_s = float(min_interval_s)
        self.refresh_s = float(refresh_s)
        self.clock = clock
        self.t0 = clock()
        self.done = 0
        self.replayed = 0
        self.label = "starting"
        self.context: dict[str, Any] = {}
        self.bench_t_s = 0.0
        self.last: OrderedDict[str, tuple[str, float]] = OrderedDict()  # instrument -> (text, bench t)
        self.curves: OrderedDict[tuple, deque] = OrderedDict()  # run key -> (x, y) points
        self.curve_label: dict[tuple, str] = {}
        # polygon runs: (shift, direction) -> {start face: [(θ, ε)]} (completed runs) and the run in progress
        self.poly_done: OrderedDict[tuple, dict] = OrderedDict()
        self.poly_run: tuple | None = None
        self.poly_pts: list[tuple[float, float]] = []
        self.status = "running"
        self.writes = 0
        self._last_write = -math.inf

    # --------------------------------------------------------------------- runner callbacks

    def start(self, n_steps: int) -> None:
        """Called by the run once it knows its procedure's length."""
        self.n_steps = int(n_steps)
        self.t0 = self.clock()
        self.write()

    def on_step(self, i: int, step: Any, context: Mapping[str, Any], replay: bool = False) -> None:
        self.done = max(self.done, i + 1)
        if replay:
            self.replayed = self.done
        self.context = dict(context)
        label = getattr(step, "label", None)
        if label:
            self.label = str(label)
        self.maybe_write()

    def on_row(self, row: Mapping[str, Any], result: Any = None) -> None:
        t = float(row.get("t_s", self.bench_t_s) or 0.0)
        self.bench_t_s = max(self.bench_t_s, t)
        for name, r in (row.get("readings") or {}).items():
            self.last[name] = (_reading_text(r), t)
        if row.get("type") == "capture":
            self.last[str(row.get("camera", "camera"))] = (f"frame {row.get('tag', {}).get('k', '?')} captured", t)
        self._plot_point(row)
        self.maybe_write()

    def _polygon_point(self, tag: Mapping[str, Any], theta: float, eps: float) -> None:
        run = (tag.get("shift_deg"), tag.get("direction"), tag.get("rep"), tag.get("start_face"))
        if run != self.poly_run:
            self._close_polygon_run()
            self.poly_run = run
        self.poly_pts.append((theta, eps))

    def _close_polygon_run(self) -> None:
        """Fold the finished run into running sums per angle: O(1) memory and work per run, so a
        run of thousands of start-face runs costs the same per page write as a short one."""
        if self.poly_run is not None and len(self.poly_pts) >= 3:
            shift, direction, rep, face = self.poly_run
            acc = self.poly_done.setdefault((shift, direction), {"runs": 0, "sum": {}})
            m = sum(e for _, e in self.poly_pts) / len(self.poly_pts)
            for th, e in self.poly_pts:
                s_c = acc["sum"].setdefault(round(th, 3), [0.0, 0])
                s_c[0] += e - m
                s_c[1] += 1
            acc["runs"] += 1
        self.poly_run, self.poly_pts = None, []

    def alpha_so_far(self) -> dict[tuple, tuple[list[float], list[float], int]]:
        """Per (shift, direction): the shift-angle α estimate from the completed start-face runs.

        Hsieh eq. 3 (docs/conventions.md): ε_ij = α(θ_i) + Σ_{k=j}^{j+i−1} β_k + U_j. Each run's
        mean over its steps removes the set-up constant U_j; the mean over the start faces j then
        tends to α(θ_i) (up to a constant) because every face appears equally often once all N
        start faces are done (Σβ = 0, eq. 1). With fewer runs the β terms do not cancel yet: the
        curve converges as the runs complete."""
        out = {}
        for key, acc in self.poly_done.items():
            th = sorted(acc["sum"])
            a = [acc["sum"][t][0] / acc["sum"][t][1] for t in th]
            mu = sum(a) / len(a)
            out[key] = (th, [x - mu for x in a], acc["runs"])
        return out

    def _plot_point(self, row: Mapping[str, Any]) -> None:
        tag = row.get("tag") or {}
        proc = tag.get("procedure")
        if proc not in _PLOT:
            return
        inst, key, _ = _PLOT[proc]
        rd = (row.get("readings") or {}).get(inst)
        enc = (row.get("readings") or {}).get("encoder") or {}
        if not isinstance(rd, Mapping) or rd.get("status", "ok") != "ok" or key not in rd:
            return
        angles = enc.get("angle_deg") or [tag.get("target_deg", 0.0)]
        x = float(angles[0]) % 360.0
        v = rd[key]
        if proc == "polygon" and isinstance(v, (int, float)) and math.isfinite(v):
            self._polygon_point(tag, x, float(v))
        if proc == "selfcal":  # the spread of two heads is what self-calibration averages out
            if not isinstance(v, (list, tuple)) or len(v) < 2:
                return
            y = (float(v[1]) - float(v[0])) * 3600.0
        else:
            y = float(v)
        if not math.isfinite(y):
            return
        run = (proc, tag.get("shift_deg"), tag.get("start_face", tag.get("polygon_start_face")), tag.get("rep"),
               tag.get("direction"))
        if run not in self.curves:
            self.curves[run] = deque(maxlen=MAX_POINTS)
            bits = [proc]
            if tag.get("shift_deg") is not None:
                bits.append(f"S = {float(tag['shift_deg']):g}°")
            if run[2] is not None:
                bits.append(f"start face {run[2]}")
            if tag.get("rep") is not None:
                bits.append(f"rep {tag['rep']}")
            if tag.get("direction"):
                bits.append(str(tag["direction"]))
            self.curve_label[run] = ", ".join(bits)
            while len(self.curves) > MAX_CURVES:
                old, _ = self.curves.popitem(last=False)
                self.curve_label.pop(old, None)
        self.curves[run].append((x, y))

    # --------------------------------------------------------------------- page

    def eta_s(self) -> float:
        """Wall seconds to go: the live steps' rate so far times the steps left (replayed steps cost nothing)."""
        live = self.done - self.replayed
        el = self.clock() - self.t0
        if live <= 0 or el <= 0:
            return float("nan")
        return (self.n_steps - self.done) * el / live

    def maybe_write(self) -> bool:
        now = self.clock()
        if now - self._last_write < self.min_interval_s:
            return False
        self.write()
        return True

    def close(self, status: str = "finished") -> None:
        """The final page; nothing when the run never started (a run refused before its first step,
        e.g. by another live run's lock on the folder, leaves that run's page alone)."""
        self.status = status
        self._close_polygon_run()
        if self.writes:
            self.write()

    def write(self) -> Path:
        self._last_write = self.clock()
        text = self.render()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # the one atomic writer; no fsync: the page is rewritten every second and only a view
        atomic_write_text(self.path, text, fsync=False)
        self.writes += 1
        return self.path

    def render(self) -> str:
        pct = 100.0 * self.done / self.n_steps if self.n_steps else 100.0
        elapsed = self.clock() - self.t0
        running = self.status == "running"
        refresh = f'<meta http-equiv="refresh" content="{self.refresh_s:g}">' if running else ""
        ctx = ", ".join(f"{html.escape(str(k))} = {html.escape(str(v))}" for k, v in self.context.items())
        rows = "".join(f"<tr><td>{html.escape(n)}</td><td class='r'>{txt}</td><td class='num'>{t:.1f} s</td></tr>"
                       for n, (txt, t) in self.last.items())
        return f"""<!DOCTYPE html><html><head><meta charset="utf-8">{refresh}
<title>{html.escape(self.title)} — live</title><style>
body{{font-family:system-ui,sans-serif;max-width:1000px;margin:1.5em auto;color:#222}}
h1{{font-size:1.4em;border-bottom:2px solid #335}} table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:.2em .5em;text-align:left;vertical-align:top}} th{{background:#eef}}
.num{{text-align:right;font-variant-numeric:tabular-nums}} .bar{{background:#ddd;height:14px;width:100%}}
.fill{{background:#1f4e9a;height:14px}} .st{{font-weight:bold}}
</style></head><body>
<h1>{html.escape(self.title)} — live view</h1>
<p>Status: <span id="status" class="st">{html.escape(self.status)}</span>.
Procedure step: <span id="step">{html.escape(self.label)}</span>{f" ({ctx})" if ctx else ""}.</p>
<div class="bar"><div class="fill" style="width:{pct:.1f}%"></div></div>
<p>Progress: <span id="progress">{self.done} / {self.n_steps} steps ({pct:.1f} %)</span>;
elapsed <span id="elapsed">{_fmt_duration(elapsed)}</span>; ETA <span id="eta">{_fmt_duration(self.eta_s()) if running else "–"}</span>;
bench time <span id="bench_time">{_fmt_duration(self.bench_t_s)}</span>.
{f"{self.replayed} steps replayed from the journal." if self.replayed else ""}</p>
<h2>Last readings</h2>
<table id="readings"><tr><th>instrument</th><th>reading</th><th>bench time</th></tr>{rows}</table>
<h2>What is known so far</h2>
{self._svg()}
<p style="color:#666;font-size:.85em">Written by benchtwin at most every {self.min_interval_s:g} s of wall time;
the page reloads every {self.refresh_s:g} s while the run goes on.</p>
</body></html>
"""

    def _svg(self) -> str:
        if not self.curves:
            return "<p id='plot'>no plotted readings yet</p>"
        last_proc = next(reversed(self.curves))[0]
        alpha = self.alpha_so_far() if last_proc == "polygon" else {}
        if alpha:
            curves = [((key, n), list(zip(th, a))) for key, (th, a, n) in alpha.items()]
            labels = {c[0]: f"S = {float(c[0][0][0] or 0):g}°, {c[0][0][1] or 'forward'}: {c[0][1]} start face(s)"
                      for c in curves}
            return self._svg_curves(curves, labels, "shift-angle α so far (″)",
                                    "Encoder error α estimated so far (Hsieh eq. 3: each completed start-face run "
                                    "minus its mean, averaged over the runs; converges as all N start faces complete)",
                                    "alpha")
        curves = [(k, list(v)) for k, v in self.curves.items() if k[0] == last_proc and v]
        return self._svg_curves(curves, self.curve_label, _PLOT[last_proc][2],
                                f"{_PLOT[last_proc][2]} against the encoder angle for the last {len(curves)} "
                                f"{last_proc} run(s)", "raw")

    def _svg_curves(self, curves: list[tuple[Any, list[tuple[float, float]]]], labels: Mapping[Any, str], ylab: str,
                    caption: str, kind: str) -> str:
        ys = [y for _, pts in curves for _, y in pts]
        y0, y1 = min(ys), max(ys)
        if y1 - y0 < 1e-12:
            y0, y1 = y0 - 1.0, y1 + 1.0
        W, H, L, B = 900, 300, 60, 30
        sx = lambda x: L + (W - L - 10) * x / 360.0  # noqa: E731
        sy = lambda y: 10 + (H - B - 10) * (1 - (y - y0) / (y1 - y0))  # noqa: E731
        colours = ["#1f4e9a", "#b5401a", "#2a8a3e", "#7a3e9a", "#c08a00", "#00858a", "#555"]
        lines = []
        for j, (k, pts) in enumerate(curves):
            pts.sort()
            p = " ".join(f"{sx(x):.1f},{sy(y):.1f}" for x, y in pts)
            lines.append(f'<polyline fill="none" stroke="{colours[j % len(colours)]}" stroke-width="1.3" points="{p}">'
                         f"<title>{html.escape(labels[k])}</title></polyline>")
        ticks = "".join(f'<text x="{L - 5}" y="{sy(v) + 4:.1f}" text-anchor="end" font-size="11">{v:.3g}</text>'
                        for v in (y0, (y0 + y1) / 2, y1))
        xt = "".join(f'<text x="{sx(a):.1f}" y="{H - 12}" text-anchor="middle" font-size="11">{a}°</text>'
                     for a in range(0, 361, 45))
        legend = "; ".join(html.escape(labels[k]) for k, _ in curves[-4:])
        return (f'<svg id="plot" data-kind="{kind}" width="{W}" height="{H}" viewBox="0 0 {W} {H}" style="border:1px solid #ccc">'
                f'<rect x="{L}" y="10" width="{W - L - 10}" height="{H - B - 10}" fill="#fafafa"/>'
                f"{ticks}{xt}{''.join(lines)}"
                f'<text x="12" y="{H / 2}" font-size="11" transform="rotate(-90 12 {H / 2})" text-anchor="middle">'
                f"{html.escape(ylab)}</text></svg>"
                f"<p id='plot_caption'>{html.escape(caption)} (latest: {legend}).</p>")


def live_path(dataset_dir: str | Path) -> Path:
    """Where the live page of a dataset goes: beside it, ``DATASET.live.html`` (not inside: the
    dataset's files stay those of the format)."""
    d = Path(dataset_dir)
    return d.parent / f"{d.name}.live.html"


def add_live_argument(p: Any) -> None:
    p.add_argument("--live", action="store_true",
                   help="write a self-refreshing HTML page beside the dataset (DATASET.live.html): step, progress, "
                        "ETA, last readings, a running plot")
    p.add_argument("--live-interval", type=float, default=1.0, metavar="S",
                   help="rewrite the live page at most every S seconds of wall time (default 1)")


def live_for(ns: Any, title: str) -> LiveView | None:
    """The LiveView a command's ``--live`` asks for (None without it). The page is an output like
    any other (``benchtwin.fsio.check_output_target``): an existing one is replaced only with
    ``--force`` or by the run it belongs to (``--resume``), never when it is an input."""
    if not getattr(ns, "live", False):
        return None
    if not (ns.live_interval > 0 and math.isfinite(ns.live_interval)):
        from benchtwin.cli import InputError

        raise InputError(f"--live-interval: expected a positive number of seconds, got {ns.live_interval}")
    from benchtwin.fsio import check_output_target

    page = check_output_target(live_path(ns.out), force=getattr(ns, "force", False) or getattr(ns, "resume", False),
                               inputs=[getattr(ns, "scenario", None), getattr(ns, "bench", None)], what="live page")
    return LiveView(page, title, 0, min_interval_s=ns.live_interval)
