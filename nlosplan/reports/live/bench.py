"""What the live view costs: an emulated ``rig capture`` timed with and without ``--live``; the server's memory
under many page loads.

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

__all__ = ["bench_live", "session_memory"]


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


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for process {pid}")


def session_memory(path, *, gets: int = 60, clients: int = 4, settle_s: float = 10.0, env=None) -> dict:
    """Resident memory of ``nlosplan serve PATH`` before and after ``gets`` page loads (Linux: ``/proc``).

    Each GET of the page makes the server build a session (a whole rig or design document) that no browser
    connects to, as a script or a scanner on this machine would; ``clients`` threads load it at once.

    Parameters
    ----------
    path : path
        What to serve (a capture store or a design folder).
    gets : int
        Page loads in all.
    clients : int
        Threads loading the page at the same time.
    settle_s : float
        Seconds to wait after the last load before the last reading (unused sessions are dropped by then).
    env : dict, optional
        The server's environment (e.g. another ``PYTHONPATH`` to measure another version of nlosplan).

    Returns
    -------
    dict
        ``rss_mb``: after the first load (the baseline), after the last, after ``settle_s``; ``growth_mb`` and
        ``settled_growth_mb`` against the baseline; ``seconds`` the loads took; the settings; ``load_1min``.
    """
    import urllib.request

    proc = subprocess.Popen([sys.executable, "-m", "nlosplan", "serve", str(path), "--port", "0"],
                            stderr=subprocess.PIPE, text=True, env=env)
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
    try:
        deadline = time.monotonic() + 120
        url = None
        while url is None:
            m = re.search(r"(http://127\.0\.0\.1:\d+/)", "".join(err))
            url = m.group(1) if m else None
            if url is None and (proc.poll() is not None or time.monotonic() > deadline):
                raise RuntimeError(f"serve did not start: {''.join(err)[-500:]}")
            time.sleep(0.1)
        urllib.request.urlopen(url, timeout=120).read()
        time.sleep(1.0)
        base = _rss_mb(proc.pid)
        load0 = os.getloadavg()[0]
        left = [gets]
        lock = threading.Lock()

        def client():
            while True:
                with lock:
                    if left[0] <= 0:
                        return
                    left[0] -= 1
                urllib.request.urlopen(url, timeout=300).read()

        t0 = time.monotonic()
        pool = [threading.Thread(target=client) for _ in range(clients)]
        for t in pool:
            t.start()
        for t in pool:
            t.join()
        seconds = time.monotonic() - t0
        after = _rss_mb(proc.pid)
        time.sleep(settle_s)
        settled = _rss_mb(proc.pid)
    finally:
        proc.terminate()
        proc.wait(timeout=60)
    return {"rss_mb": [base, after, settled], "growth_mb": after - base, "settled_growth_mb": settled - base,
            "seconds": seconds, "gets": gets, "clients": clients, "settle_s": settle_s,
            "load_1min": [load0, os.getloadavg()[0]]}
