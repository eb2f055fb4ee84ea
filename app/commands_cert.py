"""Commands of what a lab hands on (issue 20): ``certificate`` (a PTB DCC from results.json).

Registered by ``benchtwin.cli._load_commands``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from benchtwin.cli import InputError, command, force_argument


def _certificate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", type=Path, help="results.json of `benchtwin analyze` / `close-loop` / `run`")
    p.add_argument("-o", "--out", type=Path, required=True, help="the certificate to write (XML, DCC 3.1.2)")
    p.add_argument("--lab", type=Path, default=None,
                   help="lab file (TOML): laboratory, customer, item, persons, equipment, environment, dates "
                        "(example: docs/lab.example.toml); without it they are 'not stated'")
    force_argument(p, "replace an existing certificate file (default: refuse it; never an input file)")
    p.add_argument("--html", nargs="?", const="", default=None, metavar="HTML",
                   help="also write the certificate for people: a self-contained HTML page rendered from the DCC "
                        "(default path: OUT with the suffix .html)")


@command("certificate", "write a PTB Digital Calibration Certificate (DCC 3.1.2, validated offline) from results.json",
         _certificate_args)
def cmd_certificate(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.certificate import CertificateInputError, write_certificate

    try:
        html = None if ns.html is None else (Path(ns.html) if ns.html else ns.out.with_suffix(".html"))
        res = write_certificate(ns.results, ns.out, ns.lab, html_path=html, force=ns.force)
    except CertificateInputError as exc:
        raise InputError(str(exc)) from None
    return {"ok": True, **res,
            "message": f"certificate written: {res['certificate']} ({res['schema']}, {res['n_angles']} angles, "
                       f"U ≤ {res['max_U_arcsec']:.2g}″, administrative data: {res['administrative_data']})"
                       + (f"; for people: {res['html']}" if res.get("html") else "")}
