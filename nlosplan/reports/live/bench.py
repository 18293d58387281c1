"""What the live view costs a run: an emulated ``rig capture`` timed with and without ``--live``.

Each round runs the same short capture twice on the pty emulators, once plain and once with ``--live``
and ``pages`` sessions open on its page (Bokeh's Python client: the server builds each page, runs its
periodic reads and pushes every change to it, as to a browser), in alternating order. The figure is the
executor's own run time (``seconds`` of the command's JSON: moves, captures, stores; not the start-up),
so start-up noise stays out; the ratio is taken per round, against a baseline measured in the same round.
"""

from __future__ import annotations

import json
import os
import re
import statistics
import subprocess
import sys
import threading
import time

__all__ = ["bench_live"]


def _capture(store, positions: str, repeats: int, live: bool, pages: int) -> dict:
    argv = [sys.executable, "-m", "nlosplan", "rig", "capture", "--emulate", "--positions", positions,
            "--repeats", str(repeats), "--settle", "0", "--store", str(store), "--json"]
    if live:
        argv += ["--live", "0"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True)
    reader.start()
    clients = []
    if live:
        deadline = time.monotonic() + 120
        url = None
        while url is None and proc.poll() is None and time.monotonic() < deadline:
            m = re.search(r"live page at (http://\S+)", "".join(err))
            url = m.group(1) if m else None
            time.sleep(0.05)
        if url is not None:
            for _ in range(pages):
                t = threading.Thread(target=_page, args=(url,), daemon=True)
                t.start()
                clients.append(t)
    out, _ = proc.communicate()
    reader.join(timeout=5)
    if proc.returncode != 0:
        raise RuntimeError(f"rig capture failed ({proc.returncode}): {''.join(err)[-500:]}")
    res = json.loads(out)
    return {"seconds": float(res["seconds"]), "captured": int(res["captured"]), "pages": len(clients)}


def _page(url: str) -> None:
    """One session on the page, kept until the server goes away."""
    from bokeh.client import pull_session

    try:
        session = pull_session(url=url.split("?")[0])
        session.loop_until_closed()
    except Exception:  # noqa: BLE001 - the run ended and took the page with it
        pass


def bench_live(folder, *, rounds: int = 3, positions: str = "0-9", repeats: int = 3, pages: int = 1) -> dict:
    """Run time of an emulated ``rig capture`` without and with ``--live`` (``pages`` sessions open).

    Parameters
    ----------
    folder : path
        Where the rounds' stores go (one new store per run).
    rounds : int
    positions : str
        Raster grid indices of the capture (``--positions``).
    repeats : int
    pages : int
        Sessions kept open on the live page.

    Returns
    -------
    dict
        ``rounds`` (per round: ``plain_s``, ``live_s``, ``ratio``), ``median_ratio``, ``plain_s`` and
        ``live_s`` (medians), ``captures`` per run, the settings and ``load_1min`` before and after.
    """
    from pathlib import Path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    rows = []
    for k in range(rounds):
        order = (False, True) if k % 2 == 0 else (True, False)
        got = {}
        for live in order:
            got[live] = _capture(folder / f"round{k}_{'live' if live else 'plain'}.db", positions, repeats, live,
                                 pages)
        rows.append({"plain_s": got[False]["seconds"], "live_s": got[True]["seconds"],
                     "ratio": got[True]["seconds"] / got[False]["seconds"], "pages": got[True]["pages"],
                     "first": "plain" if order[0] is False else "live"})
    return {"rounds": rows, "median_ratio": statistics.median(r["ratio"] for r in rows),
            "plain_s": statistics.median(r["plain_s"] for r in rows),
            "live_s": statistics.median(r["live_s"] for r in rows), "captures": got[False]["captured"],
            "positions": positions, "repeats": repeats, "pages": pages,
            "load_1min": [load0, os.getloadavg()[0]], "cpus": os.cpu_count()}
