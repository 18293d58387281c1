"""The live view: web pages over the files a design or rig run writes (``nlosplan serve``, ``--live``).

- :mod:`.design_watch`, :mod:`.rig_watch` — read a design folder, a capture store and a ``rig run``
  folder while the run writes them (polling, read-only; no second source of truth);
- :mod:`.design_page`, :mod:`.rig_page`, :mod:`.rig_approval` — the Bokeh documents of the pages and
  the approval panel (approve, edit on the map, refuse);
- :mod:`.server` — the Bokeh server on a bound socket, the token check;
- :mod:`.html` — tables and numbers as the pages show them.

Bokeh is imported only when a page is built or served.
"""
