"""Progress of long work on one line: bus-free, for replay, plot, ``run`` and benchmarks.

On a terminal the line is redrawn in place (at most ``hz`` times a second); otherwise (CI
logs, pipes) a plain line is printed every ``every_s`` seconds and once at the end, so logs
stay short. Output goes to stderr by default, leaving stdout for READY lines and results.

    with Progress(total=len(items), label="replay", unit="msg") as p:
        for item in items:
            ...
            p.update(1, note=f"t={t:.1f}s")
"""
from __future__ import annotations

import sys
import time
from typing import TextIO


def _fmt_duration(s: float) -> str:
    s = max(0, int(round(s)))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


class Progress:
    """A single progress line. ``total=None`` for open-ended work (counts and rate only).

    label: what is progressing; unit: what is counted (e.g. "msg", "frame"); stream: where
    to write (stderr); tty: force terminal (True) or log (False) style, default auto;
    every_s: period of log-style lines (s); hz: redraw limit on a terminal (1/s);
    enabled: False makes every call a no-op (e.g. ``--quiet``).
    """

    def __init__(self, total: int | float | None = None, label: str = "", unit: str = "",
                 *, stream: TextIO | None = None, tty: bool | None = None,
                 every_s: float = 5.0, hz: float = 10.0, enabled: bool = True):
        self.total = total
        self.label = label
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        if tty is None:
            isatty = getattr(self.stream, "isatty", None)
            tty = bool(isatty and isatty())
        self.tty = tty
        self.every_s = float(every_s)
        self.min_dt = 1.0 / hz if hz > 0 else 0.0
        self.enabled = enabled
        self.done: float = 0
        self.note = ""
        self.t0 = time.monotonic()
        self._last = -1e9
        self._width = 0
        self._closed = False

    # -- counting
    def update(self, n: float = 1, note: str | None = None) -> None:
        """Add ``n`` to the count (and optionally replace the note); maybe redraw."""
        self.set(self.done + n, note)

    def set(self, done: float, note: str | None = None) -> None:
        """Set the count to ``done``; maybe redraw."""
        self.done = done
        if note is not None:
            self.note = note
        if not self.enabled or self._closed:
            return
        now = time.monotonic()
        if now - self._last >= (self.min_dt if self.tty else self.every_s):
            self._last = now
            self._emit(final=False)

    def close(self, note: str | None = None) -> None:
        """Print the final line (always, once)."""
        if self._closed:
            return
        if note is not None:
            self.note = note
        if self.enabled:
            self._emit(final=True)
        self._closed = True

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- text
    def line(self) -> str:
        """The current progress text (no newline)."""
        el = time.monotonic() - self.t0
        rate = self.done / el if el > 0 else 0.0
        unit = f" {self.unit}" if self.unit else ""
        parts = [f"{self.label}:" if self.label else ""]
        if self.total:
            frac = min(1.0, max(0.0, self.done / self.total))
            parts.append(f"{self._num(self.done)}/{self._num(self.total)}{unit} ({100 * frac:3.0f}%)")
        else:
            parts.append(f"{self._num(self.done)}{unit}")
        parts.append(f"{rate:.1f}{unit}/s" if rate < 100 else f"{rate:.0f}{unit}/s")
        parts.append(f"elapsed {_fmt_duration(el)}")
        if self.total and 0 < self.done < self.total and rate > 0:
            parts.append(f"eta {_fmt_duration((self.total - self.done) / rate)}")
        if self.note:
            parts.append(self.note)
        return " ".join(p for p in parts if p)

    @staticmethod
    def _num(v: float) -> str:
        return str(int(v)) if float(v).is_integer() else f"{v:.1f}"

    def _emit(self, final: bool) -> None:
        text = self.line()
        try:
            if self.tty:
                pad = max(0, self._width - len(text))
                self.stream.write("\r" + text + " " * pad + ("\n" if final else ""))
                self._width = len(text)
            else:
                self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # closed stream: progress is never worth a crash
            self.enabled = False
