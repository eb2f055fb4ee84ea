"""docs/architecture.md's drawing is the tree (issue 35): every folder it draws exists and is
installed under the name it states (setup.py's package map), every code folder setup.py installs is
drawn, the floor lists exactly the floor modules of the layers contract, and the layers are drawn
top to bottom in the contract's order (pyproject.toml [tool.importlinter])."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
# setup.py's package map: these top-level folders are installed as benchtwin.<folder>
FOLDERS = tuple(re.search(r"^FOLDERS = \((.*?)\)", (ROOT / "setup.py").read_text(), flags=re.M).group(1)
                .replace('"', "").replace(" ", "").split(","))
DATA_FOLDERS = ("models", "scenarios")   # data packages: drawn, no code layer
CODE_FOLDERS = tuple(f for f in FOLDERS if f not in DATA_FOLDERS)


def drawing(text: str | None = None) -> str:
    """The first fenced block of the page: the layer drawing."""
    text = DOC.read_text() if text is None else text
    return text.split("```", 2)[1]


def drawn_rows(block: str) -> list[tuple[str, str]]:
    """(folder, installed name) of each row that starts with a folder ``name/`` and a ``benchtwin.x`` name."""
    return re.findall(r"^ ?([a-z_]+/)\s+(benchtwin(?:\.[a-z_]+)?)\b", block, flags=re.M)


def layers_contract() -> list[list[str]]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    (layers,) = [c for c in cfg["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    return [[m.strip() for m in layer.split(":")] for layer in layers["layers"]]


def problems(block: str) -> list[str]:
    out: list[str] = []
    rows = drawn_rows(block)
    for folder, name in rows:
        if not (ROOT / folder).is_dir():
            out.append(f"{folder} is drawn but not in the tree")
        elif folder.rstrip("/") in CODE_FOLDERS and name != f"benchtwin.{folder.rstrip('/')}":
            out.append(f"{folder} is drawn as {name}, installed as benchtwin.{folder.rstrip('/')}")
    drawn = {f.rstrip("/") for f, _ in rows}
    for folder in CODE_FOLDERS + ("benchtwin",):
        if folder not in drawn:
            out.append(f"{folder}/ is installed but not drawn")
    for folder in DATA_FOLDERS:
        if f"{folder}/" not in block:
            out.append(f"{folder}/ is installed but not drawn")
    # the layers, top to bottom, in the contract's order (the CLI/app layer first, the floor last)
    order = [name for _, name in rows]
    top = [layer[0].rsplit(".", 1)[-1] if layer[0] != "benchtwin.cli" else "app" for layer in layers_contract()[:-1]]
    pos = [next((i for i, (f, _) in enumerate(rows) if f.rstrip("/") == t), -1) for t in top]
    if pos != sorted(pos) or -1 in pos:
        out.append(f"layers drawn in the order {order}, the contract's is {top} over the floor")
    # the floor: exactly the floor modules of the contract
    floor = {m.rsplit(".", 1)[-1] for m in layers_contract()[-1]}
    m = re.search(r"^ ?benchtwin/\s+benchtwin\.(units(?: · [a-z_]+)*)", block, flags=re.M)
    if m is None:
        out.append("the floor row (benchtwin/ benchtwin.units · …) is not drawn")
    else:
        drawn_floor = {x.strip() for x in m.group(1).split("·")}
        if drawn_floor != floor:
            out.append(f"floor drawn {sorted(drawn_floor)}, the contract's {sorted(floor)}")
        if not floor <= {p.stem for p in (ROOT / "benchtwin").glob("*.py")}:
            out.append("a floor module of the contract is not a file of benchtwin/")
    return out


def test_the_drawing_is_the_tree():
    assert "twin" in CODE_FOLDERS and "models" in FOLDERS, FOLDERS   # setup.py was read
    assert problems(drawing()) == []


def test_the_check_fails_on_a_drawing_that_is_not_the_tree():
    block = drawing()
    assert any("not in the tree" in p for p in problems(block.replace(" hw/ ", " hwx/ ")))
    assert any("installed but not drawn" in p for p in problems(block.replace(" app/ ", " xpp/ ")))
    assert any("floor drawn" in p for p in problems(block.replace(" · heap", "")))
    swapped = block.replace(" twin/ ", " TMP/ ").replace(" hw/ ", " twin/ ").replace(" TMP/ ", " hw/ ")
    assert any("layers drawn" in p for p in problems(swapped))
