"""The report of a design study: the target verdict, figures, a written summary (Markdown and HTML)
and one self-contained ``report.html``.

Why a module of its own: the study's tables (``execution``) are the data; this is how a
metrologist reads them. The verdict states, along the target parameter, which swept values keep
``mean + k·u`` (criterion "mean", u = s/√n the standard uncertainty of the mean, GUM 4.2.3) or
``mean + k·s`` ("individual": a single run) below the target, with k the coverage factor (GUM 6.2),
and where that bound crosses the target (linear interpolation between neighbouring points). The
HTML report uses the analysis report's format (``benchtwin.analysis.report.html.Report``: figures
as PNG data URIs, so the file can be mailed or archived alone).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.fsio import atomic_write_text

from .spec import Study, _output_dim


@dataclass(frozen=True)
class RunInfo:
    """How a study run went (the report's header and ``study.json``)."""

    fid_map: dict[str, str]  # output -> fidelity that computed it
    fidelity: str  # what every point ran: "physics" | "full"
    version: str  # code_version() of the run
    computed: int  # (point, rep) pairs computed now
    cached: int  # (point, rep) pairs taken from the cache
    wall_s: float
    where: str  # the executor, in words
    overrides: Mapping[str, Any] | None = None  # --set / --seed, as given (study.json only)
    notes: tuple[str, ...] = ()  # the unusable cache entries recomputed (study.json only)

    def run_label(self, study: Study) -> str:
        """What every row ran: physics, full (simulate → analyze) or full+close_loop, or the custom
        point function's name."""
        if any(v.startswith("custom:") for v in self.fid_map.values()):
            return next(iter(self.fid_map.values()))
        if self.fidelity == "full":
            return "full+close_loop" if study.close_loop else "full"
        return self.fidelity


@dataclass(frozen=True)
class Written:
    verdict: dict[str, Any] | None
    figures: list[Path]
    report: Path


def write_report(study: Study, rows: list[dict[str, Any]], done: dict[tuple[int, int], dict[str, Any]],
                 out: Path, info: RunInfo) -> Written:
    """``summary.md``, ``summary.html``, ``figures/*.png`` and ``report.html`` under ``out``."""
    verdict = _target_verdict(study, rows) if study.target else None
    figures = _figures(study, rows, done, out, verdict)
    md = _markdown(study, rows, verdict, info)
    atomic_write_text(out / "summary.md", md)
    atomic_write_text(out / "summary.html", _html(md))
    report = _report(study, _html(md), figures, out / "report.html")
    return Written(verdict, figures, report)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _target_verdict(study: Study, rows: list[dict]) -> dict[str, Any]:
    """Along the target parameter (for each combination of the other parameters): which values keep
    ``mean + k·u`` (criterion "mean") or ``mean + k·s`` ("individual") below the target, and where the
    upper bound crosses the target (linear interpolation between neighbouring points)."""
    t = study.target
    assert t is not None
    param = next(p for p in study.parameters if p.name == t.parameter)
    unit, _ = _output_dim(t.output)
    # group by the other grid parameters; sampled (random/lhs) ones vary within a group
    others = [p.name for p in study.parameters if p.name != t.parameter and p.sampling == "grid"]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(repr(r["values"][o]) for o in others), []).append(r)
    result_groups: list[dict[str, Any]] = []
    for gkey, grs in groups.items():
        numeric = param.kind in ("quantity", "int", "number")
        if numeric:
            grs = sorted(grs, key=lambda r: r["values"][t.parameter])
        xs, ups, oks = [], [], []
        for r in grs:
            mean, std, u = r[t.output]
            spread = std if t.criterion == "individual" else u
            upper = mean + t.coverage * (spread if math.isfinite(spread) else 0.0)
            xs.append(r["values"][t.parameter])
            ups.append(upper)
            oks.append(upper < t.below)
        crossing = None
        if numeric:
            for i in range(len(xs) - 1):
                if oks[i] != oks[i + 1]:
                    x0, x1, y0, y1 = float(xs[i]), float(xs[i + 1]), ups[i], ups[i + 1]
                    crossing = x0 + (t.below - y0) * (x1 - x0) / (y1 - y0) if y1 != y0 else x0
                    break
        good = [x for x, ok in zip(xs, oks) if ok]
        label = ", ".join(f"{o} = {_fmt(grs[0]['values'][o])}" for o in others)
        result_groups.append({"others": {o: grs[0]["values"][o] for o in others}, "values_ok": good,
                              "upper": ups, "values": xs, "crossing": crossing, "label": label})
    pu = f" {param.unit}" if param.unit else ""
    bound = f"mean + {t.coverage:g}·{'s' if t.criterion == 'individual' else 'u'}"
    sentences = []
    for g in result_groups:
        where = f" ({g['label']})" if g["label"] else ""
        if not g["values_ok"]:
            s = f"no swept value of {param.name} keeps {t.output} ({bound}) below {t.below:g} {unit}{where}"
        elif len(g["values_ok"]) == len(g["values"]):
            s = f"every swept value of {param.name} keeps {t.output} ({bound}) below {t.below:g} {unit}{where}"
        else:
            ok = ", ".join(_fmt(v) for v in g["values_ok"])
            s = f"{t.output} ({bound}) stays below {t.below:g} {unit} for {param.name} = {ok}{pu}{where}"
            if g["crossing"] is not None:
                s += f"; the bound crosses the target at {param.name} ≈ {g['crossing']:.3g}{pu}"
        sentences.append(s)
    return {"output": t.output, "below": t.below, "unit": unit, "parameter": param.name,
            "parameter_unit": param.unit, "criterion": t.criterion, "coverage": t.coverage,
            "groups": result_groups, "sentence": "; ".join(sentences) + "."}


def _figures(study: Study, rows: list[dict], done: dict, out: Path, verdict: dict | None) -> list[Path]:
    """Each output against the first numeric parameter: mean with a k·u band, individual reps as dots,
    one line per combination of the other parameters, and the target as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    numeric = [p for p in study.parameters if p.kind in ("quantity", "int", "number")]
    if not numeric:
        return []
    xp = next((p for p in numeric if study.target and p.name == study.target.parameter), numeric[0])
    others = [p.name for p in study.parameters if p.name != xp.name and p.sampling == "grid"]
    scattered = any(p.sampling != "grid" for p in study.parameters)  # no lines through sampled points
    k = study.target.coverage if study.target else 2.0
    figdir = out / "figures"
    figdir.mkdir(exist_ok=True)
    paths = []
    for o in study.outputs:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        groups: dict[tuple, list[dict]] = {}
        for r in rows:
            groups.setdefault(tuple(repr(r["values"][n]) for n in others), []).append(r)
        for gi, grs in enumerate(groups.values()):
            grs = sorted(grs, key=lambda r: r["values"][xp.name])
            x = np.array([r["values"][xp.name] for r in grs], float)
            m = np.array([r[o][0] for r in grs])
            u = np.nan_to_num(np.array([r[o][2] for r in grs]))
            s = np.nan_to_num(np.array([r[o][1] for r in grs]))
            label = ", ".join(f"{n} = {_fmt(grs[0]['values'][n])}" for n in others) or "mean"
            if scattered:
                line = ax.errorbar(x, m, yerr=k * u, fmt="o", ms=4, capsize=2, label=label).lines[0]
            else:
                line, = ax.plot(x, m, "o-", ms=4, label=label)
                ax.fill_between(x, m - k * s, m + k * s, color=line.get_color(), alpha=0.12, lw=0)
                ax.fill_between(x, m - k * u, m + k * u, color=line.get_color(), alpha=0.35, lw=0)
            for r in grs:
                reps = [done[(r["point"], j)]["outputs"][o] for j in range(study.repetitions)]
                ax.plot([r["values"][xp.name]] * len(reps), reps, ".", color=line.get_color(), ms=2, alpha=0.5)
        if study.target and study.target.output == o:
            unit, _ = _output_dim(o)
            ax.axhline(study.target.below, ls="--", color="k", lw=1, label=f"target {study.target.below:g} {unit}")
            if verdict and study.target.parameter == xp.name:
                for g in verdict["groups"]:
                    if g["crossing"] is not None:
                        ax.axvline(g["crossing"], ls=":", color="0.3", lw=1)
                        ax.annotate(f"{g['crossing']:.3g} {xp.unit}", (g["crossing"], study.target.below),
                                    textcoords="offset points", xytext=(4, 6), fontsize=8)
        ax.set_xlabel(xp.column)
        ax.set_ylabel(o)
        bands = (f"error bars ± {k:g}·u(mean); other sampled parameters vary between points" if scattered else
                 f"dark band ± {k:g}·u(mean), light band ± {k:g}·s (single run)")
        ax.set_title(f"{study.name}: {o}\nmean over {study.repetitions} reps; {bands}; dots: single runs",
                     fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = figdir / f"{o}_vs_{xp.column}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def _markdown(study: Study, rows: list[dict[str, Any]], verdict: dict[str, Any] | None, info: RunInfo) -> str:
    fid_map = info.fid_map
    lines = [f"### Study `{study.name}`", ""]
    if study.description:
        lines += [study.description, ""]
    lines += [f"Base scenario `{study.base_ref}`, seed {study.seed}, {len(rows)} points × "
              f"{study.repetitions} repetitions ({info.computed} computed, {info.cached} from cache, "
              f"{info.wall_s:.1f} s, {info.where}); code {info.version}.", ""]
    if study.fixed:
        lines += ["Fixed for every point: " + ", ".join(f"`{k} = {v}`" for k, v in study.fixed.items()) + ".", ""]
    lines += ["Fidelity per output: " + ", ".join(f"`{o}`: {f}" for o, f in fid_map.items()) + ".", ""]
    used = set(fid_map.values())
    legend = {"physics": "physics = the twin's MuJoCo statics and the exact reading of the posed disk (no images, "
                         "no instruments, no analysis)",
              "full": "full = simulate the whole dataset (rendered CCD images, every instrument) and analyse it "
                      f"with the one pipeline (Fourier order {study.order}), one simulated bench per repetition",
              "full+close_loop": "full+close_loop = the same plus the close-the-loop step"}
    notes = [text for key, text in legend.items() if key in used or
             (key == "full" and any(v.startswith("physics (") or v == "full+close_loop" for v in used))]
    if notes:
        lines += ["; ".join(notes) + ".", ""]
    if verdict:
        lines += [f"**Target**: {verdict['sentence']}", ""]
    head = [p.column for p in study.parameters] + [f"{o} [{fid_map[o]}] (mean ± u, s)" for o in study.outputs]
    lines += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        cells = [_fmt(r["values"][p.name]) for p in study.parameters]
        cells += [f"{r[o][0]:.4g} ± {r[o][2]:.2g}, {r[o][1]:.2g}" for o in study.outputs]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    return "\n".join(lines)


def _report(study: Study, summary_html: str, figures: list[Path], path: Path) -> Path:
    """The study's self-contained report: the written summary, then every figure embedded (PNG data
    URIs, the analysis report's format), so it can be mailed or archived alone."""
    import base64
    import html as _h

    from benchtwin.analysis.report.html import Report

    rep = Report(f"Design study {study.name}")
    rep.blocks.append(summary_html)
    rep.heading("Figures")
    for f in figures:
        data = base64.b64encode(Path(f).read_bytes()).decode()
        cap = f"{Path(f).stem.replace('_vs_', ' vs ')}: mean over the repetitions with its bands (see the summary)"
        rep.blocks.append(f'<figure><img alt="{_h.escape(cap)}" src="data:image/png;base64,{data}">'
                          f"<figcaption>{_h.escape(cap)}</figcaption></figure>")
    return rep.write(path)


def _html(md: str) -> str:
    """A small HTML snippet of the markdown summary (headings, paragraphs, one table)."""
    import html as _h

    out, in_table = ["<section class=\"study-summary\">"], False
    for line in md.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if all(set(c) <= {"-", " "} for c in cells):
                continue
            if not in_table:
                out.append("<table>")
                in_table = True
                out.append("<tr>" + "".join(f"<th>{_h.escape(c)}</th>" for c in cells) + "</tr>")
            else:
                out.append("<tr>" + "".join(f"<td>{_h.escape(c)}</td>" for c in cells) + "</tr>")
            continue
        if in_table:
            out.append("</table>")
            in_table = False
        if line.startswith("### "):
            out.append(f"<h3>{_h.escape(line[4:].replace('`', ''))}</h3>")
        elif line.strip():
            text = _h.escape(line).replace("**", "")
            text = re.sub(r"`([^`]*)`", r"<code>\1</code>", text)
            out.append(f"<p>{text}</p>")
    if in_table:
        out.append("</table>")
    out.append("</section>")
    return "\n".join(out) + "\n"
