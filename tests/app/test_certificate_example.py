"""docs/certificate.example.xml is generated, not edited (issue 34 item 8): the default scenario run
with the analytic CCD renderer, certified with docs/lab.example.toml, must give the file byte for
byte. Nothing in it varies between runs (dates and id come from the lab file, the release is the
package's, the lab file is named as given, relative to the checkout), so nothing is normalised. Slow (the whole default run): ``pytest -m slow`` this file.

The example itself is checked on every run of the suite: it validates against the shared schemas
and carries the DCC's basic_* refTypes."""

from __future__ import annotations

from pathlib import Path

import pytest
from lxml import etree

from benchtwin.app.certificate import validation_errors
from benchtwin.cli import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "docs" / "certificate.example.xml"
SHARED_DCC = ROOT.parent / "shared" / "dcc"
REGENERATE = ("regenerate: benchtwin run -o OUT --backend analytic && benchtwin certificate OUT/results.json "
              "-o docs/certificate.example.xml --lab docs/lab.example.toml")


def test_the_example_validates_and_uses_the_basic_reftypes():
    if not (SHARED_DCC / "dcc.xsd").is_file():
        pytest.skip("../shared/dcc (the reference schemas) is not beside this checkout")
    tree = etree.parse(str(EXAMPLE))
    assert validation_errors(tree, SHARED_DCC) == []
    refs = {r for q in tree.iter("{https://ptb.de/dcc}quantity") for r in (q.get("refType") or "").split()}
    assert {"basic_measuredValue", "basic_referenceValue", "basic_measurementError"} <= refs


@pytest.mark.slow
def test_the_example_is_what_the_code_writes(tmp_path, monkeypatch):
    out = tmp_path / "run"
    assert main(["run", "-o", str(out), "--backend", "analytic", "--quiet"]) == 0
    cert = tmp_path / "example.xml"
    # the environment's source names the lab file as given: docs/lab.example.toml, from the checkout
    monkeypatch.chdir(ROOT)
    assert main(["certificate", str(out / "results.json"), "-o", str(cert), "--lab", "docs/lab.example.toml",
                 "--quiet"]) == 0
    assert cert.read_text(encoding="utf-8") == EXAMPLE.read_text(encoding="utf-8"), REGENERATE
