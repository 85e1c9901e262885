"""A progress line on standard error for long runs (only when it is a terminal)."""

from __future__ import annotations

import sys
import time


def with_progress(chunks, total, enabled, label="sampling"):
    """Pass ``chunks`` through, redrawing ``label: 42% 420,000/1,000,000`` at most 5 times a second.

    Nothing is drawn for runs shorter than half a second.
    """
    if not enabled or not total:
        yield from chunks
        return
    start = last = time.monotonic()
    done = 0
    shown = False
    for chunk in chunks:
        done += len(chunk)
        now = time.monotonic()
        if now - start > 0.5 and (now - last > 0.2 or done == total):
            last = now
            shown = True
            rate = done / max(now - start, 1e-9)
            eta = (total - done) / rate if rate else 0
            sys.stderr.write(f"\r{label}: {100 * done / total:5.1f}% {done:,}/{total:,} points, "
                             f"{now - start:.1f} s, {eta:.0f} s left   ")
            sys.stderr.flush()
        yield chunk
    if shown:
        sys.stderr.write("\n")
        sys.stderr.flush()
