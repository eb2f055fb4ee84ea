"""The HTML report: one self-contained file (figures embedded as PNG data URIs), so a report can be
mailed or archived with its dataset without losing pictures.

``Report`` collects sections (headings, paragraphs, key/value tables with units and uncertainties,
figures) and ``write(path)`` renders them. Figures are matplotlib Figures rendered with the Agg
backend (no screen needed), drawn once at their own size (each figure places its axes with fixed
margins, analysis/report/layout.py: no layout engine's dry run, no ``bbox_inches="tight"`` second
draw), and closed after rendering (pyplot ones) to keep memory flat over long studies.

Both cores (issue #17): the figures are kept as they are added and drawn when the report is
rendered, by this process and a forked child taking them in turn as each is free
(``benchtwin.forkcall``: the child sees the figures as they are, nothing is pickled but the PNG
bytes it sends back). Agg draws the same bytes in either process, so the report is the same file;
with one figure, or ``BENCHTWIN_FORK=0``, all are drawn here.
"""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: resolution of the report's embedded figures
FIGURE_DPI = 110
#: zlib level of the embedded PNGs: measured on the default report's ten figures, level 3 encodes
#: in 0.29 s CPU against level 6's (PIL's default) 0.45 s and gives a smaller report (1.97 against
#: 2.12 MB; the noisy polar plots compress better at 3), docs/benchmarks.md
PNG_COMPRESS_LEVEL = 3

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222;line-height:1.4}
h1{border-bottom:2px solid #335;padding-bottom:.2em} h2{margin-top:2em;color:#335}
table{border-collapse:collapse;margin:.5em 0} td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}
th{background:#eef} td.num{text-align:right;font-variant-numeric:tabular-nums}
figure{margin:1em 0} figcaption{font-size:.9em;color:#555} img{max-width:100%}
.note{background:#fff8e0;border-left:4px solid #d9a400;padding:.4em .8em}
"""


@dataclass
class Report:
    title: str
    blocks: list[str] = field(default_factory=list)
    #: figures not drawn yet: (index of their block, Figure, caption)
    _pending: list[tuple[int, Any, str]] = field(default_factory=list, repr=False)

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, note: bool = False) -> None:
        cls = ' class="note"' if note else ""
        self.blocks.append(f"<p{cls}>{html.escape(text)}</p>")

    def table(self, rows: list[list[Any]], header: list[str] | None = None) -> None:
        out = ["<table>"]
        if header:
            out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
        for row in rows:
            out.append("<tr>" + "".join(_td(v) for v in row) + "</tr>")
        out.append("</table>")
        self.blocks.append("".join(out))

    def figure(self, fig: Any, caption: str) -> None:
        """Add a figure; it is drawn when the report is rendered (``render``/``write``)."""
        self._pending.append((len(self.blocks), fig, caption))
        self.blocks.append("")

    def _draw_pending(self) -> None:
        import os

        from benchtwin.forkcall import ForkCall

        todo, self._pending = self._pending, []
        figs = [f for _, f, _ in todo]
        pngs: dict[int, bytes] = {}
        if len(figs) < 2:
            pngs = {i: _png(f) for i, f in enumerate(figs)}
        else:
            # The figures' indices wait in a pipe; this process and a forked child each take the
            # next one as they finish the last (a read of 2 bytes takes one index whole: a pipe's
            # reads are serialised), so the costly polar plots spread over both cores whatever
            # their order. Who draws which figure never changes its bytes.
            r, w = os.pipe()
            os.write(w, b"".join(i.to_bytes(2, "little") for i in range(len(figs))))
            os.close(w)

            def draw_taken() -> dict[int, bytes]:
                out = {}
                while (b := os.read(r, 2)):
                    i = int.from_bytes(b, "little")
                    out[i] = _png(figs[i])
                return out

            try:
                with ForkCall(draw_taken, what="the report's figures") as child:
                    pngs = draw_taken()
                    pngs.update(child.wait())
            finally:
                os.close(r)
        for i, (at, fig, caption) in enumerate(todo):
            _release(fig)
            data = base64.b64encode(pngs[i]).decode()
            self.blocks[at] = (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
                               f"<figcaption>{html.escape(caption)}</figcaption></figure>")

    def render(self) -> str:
        if self._pending:
            self._draw_pending()
        body = "\n".join(self.blocks)
        return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(self.title)}</title>"
                f"<style>{_CSS}</style></head><body><h1>{html.escape(self.title)}</h1>\n{body}\n</body></html>\n")

    def write(self, path: str | Path) -> Path:
        from benchtwin.fsio import atomic_write_text

        return atomic_write_text(path, self.render())


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    # drawn once, at the figure's own size: the figures place their axes themselves (fixed margins,
    # layout.py), so bbox_inches="tight" (a second full draw to measure the extent) is not needed
    fig.savefig(buf, format="png", dpi=FIGURE_DPI, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def _release(fig: Any) -> None:
    import sys

    if "matplotlib.pyplot" in sys.modules:  # a pyplot figure must be released; a bare Figure is not registered
        sys.modules["matplotlib.pyplot"].close(fig)


def _td(v: Any) -> str:
    if isinstance(v, float):
        return f'<td class="num">{v:.4g}</td>'
    if isinstance(v, int) and not isinstance(v, bool):
        return f'<td class="num">{v}</td>'
    return f"<td>{html.escape(str(v))}</td>"


#: said once where a report's values start (not after each value: issue 34's "printed 40 times")
U_CONVENTION = "± is the standard uncertainty u (k = 1) wherever no coverage factor k is stated."


def value_with_u(x: float, u: float, unit: str, k: float | None = None) -> str:
    """'7.10 ± 0.05 µm' with u shown to two significant digits and x rounded to match (GUM 7.2.6).
    Without ``k`` the ± is the standard uncertainty, which the report states once (``U_CONVENTION``);
    with ``k`` it is an expanded uncertainty and says so: '… (k = 2)'."""
    import math

    if not (math.isfinite(u) and u > 0):
        return f"{x:.4g} {unit}"
    digits = max(0, 1 - int(math.floor(math.log10(u))))
    s = f"{x:.{digits}f} ± {u:.{digits}f} {unit}"
    return s + (f" (k = {k:g})" if k else "")
