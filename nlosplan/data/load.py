"""One loader of captures from a store, for every room that learns from them (design planner, studies)."""

from __future__ import annotations

from nlosplan.data.dataset import Dataset
from nlosplan.data.records import describe
from nlosplan.data.store import CaptureStore
from nlosplan.errors import UserError

__all__ = ["check_captures", "load_dataset"]


def load_dataset(store, where: dict | None = None, *, default_zones: str | None = None,
                 drop_backgrounds: bool = False, zones_hint: str = "") -> Dataset:
    """The captures of a store that match a label filter, as a :class:`Dataset`.

    Parameters
    ----------
    store : str or Path
        A :class:`~nlosplan.data.store.CaptureStore` file (opened read-only, never created or changed).
    where : dict, optional
        Label filter as :meth:`CaptureStore.load <nlosplan.data.store.CaptureStore.load>`
        takes it (a value may be a list).
    default_zones : str, optional
        Zone mode (e.g. ``"3x3"``) used when ``where`` names none.
    drop_backgrounds : bool
        Leave out DENALI's background captures (class group ``"background"``:
        no object, bare mount), which belong to none of the 30 shapes.
    zones_hint : str
        What the caller needs, added to the message when the store holds no
        captures of the zone mode.

    Returns
    -------
    Dataset
        Histograms (N, rows, cols, bins), counts per capture (repeats kept).

    Raises
    ------
    UserError
        The store does not exist, holds no captures of the zone mode (the
        message lists the modes it has), nothing matches the filter, or only
        backgrounds match when they are dropped.
    """
    where = check_captures(store, where, default_zones=default_zones, drop_backgrounds=drop_backgrounds,
                           zones_hint=zones_hint)
    with CaptureStore(store, readonly=True) as st:
        ds = st.load(**where)
    if drop_backgrounds:
        ds = ds.take(ds.labels["class_group"].astype(str).to_numpy() != "background")
    return ds


def check_captures(store, where: dict | None = None, *, default_zones: str | None = None, drop_backgrounds: bool = False,
                   zones_hint: str = "") -> dict:
    """Check, without loading histograms, that ``store`` holds captures matching ``where``; return the filter used.

    Parameters and errors as :func:`load_dataset` (a quick look at the labels only).
    """
    where = dict(where or {})
    if default_zones is not None:
        where.setdefault("zones", default_zones)
    with CaptureStore(store, readonly=True) as st:
        if "zones" in where and st.count(zones=where["zones"]) == 0:
            modes = sorted(st.labels()["zones"].astype(str).unique())
            have = f"it holds {', '.join(modes)} captures" if modes else "it is empty"
            hint = f"; {zones_hint}" if zones_hint else ""
            raise UserError(f"capture store {store} has no {where['zones']} captures ({have}){hint}")
        if st.count(**where) == 0:
            raise UserError(f"no captures in {store} match {describe(where)}")
        if drop_backgrounds and (st.labels(**where)["class_group"].astype(str) == "background").all():
            raise UserError(f"only background captures (no object) in {store} match {describe(where)}")
    return where
