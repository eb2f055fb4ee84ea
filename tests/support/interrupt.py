"""A power cut in the middle of a run: a method of the twin's instruments that raises
KeyboardInterrupt once it has been called ``after`` times (the kill-and-resume tests)."""

from __future__ import annotations

from typing import Any


def power_cut_after(monkeypatch: Any, cls: type, method: str, after: int) -> Any:
    """``cls.method`` works ``after`` times, then raises KeyboardInterrupt("power cut"); returns the
    original method, to put back before the resume (``monkeypatch.setattr(cls, method, orig)``)."""
    calls = {"n": 0}
    orig = getattr(cls, method)

    def flaky(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] > after:
            raise KeyboardInterrupt("power cut")
        return orig(self, *a, **kw)

    monkeypatch.setattr(cls, method, flaky)
    return orig
