"""Where a design run keeps its reference data: one name per zone layout, per world, and for real captures.

The names carry the content key of what was simulated (:meth:`~nlosplan.planner.design.data.SceneSet.key` of the
layout's sensor, :meth:`~nlosplan.planner.design.space.DesignSpace.layout_sensor`), so a run reuses a reference
saved with the same configuration, and an evaluation's key (the reference by file name) stays the same when OUT
moves. The run (:mod:`~nlosplan.planner.design.run`) simulates them; the progress page
(:mod:`~nlosplan.planner.design.progress`) names the same files without simulating anything.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from nlosplan.planner.design.space import DesignSpace, layout_name

__all__ = ["reference_paths", "real_reference_path", "world_reference_path"]


def reference_paths(out, space: DesignSpace, scenes) -> dict[str, Path]:
    """``layout -> OUT/reference/RxC_KEY.npz``: the simulated reference of every zone layout of the space.

    Parameters
    ----------
    out : str or Path
        The run's output folder.
    space : DesignSpace
    scenes : SceneSet
        The run's scenes.
    """
    return {layout_name(z): Path(out) / "reference" / f"{layout_name(z)}_{scenes.key(space.layout_sensor(z))}.npz"
            for z in space.zones}


def real_reference_path(out, real) -> Path:
    """``OUT/reference/real_HASH.npz``: the reference of a run's real captures (``real``: the store's path)."""
    return Path(out) / "reference" / f"real_{hashlib.sha1(str(real).encode()).hexdigest()[:8]}.npz"


def world_reference_path(out, index: int, layout: str, scenes, sensor) -> Path:
    """``OUT/reference/world{index}_{layout}_KEY.npz``: a layout's reference in world ``index``.

    ``scenes`` carries the world's scene arguments and ``sensor`` is the layout's sensor in that world.
    """
    return Path(out) / "reference" / f"world{index}_{layout}_{scenes.key(sensor)}.npz"
