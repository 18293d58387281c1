"""Stability-catalog scenes of the scene physics: mixed object reflectance and the object mount.

Scene builders and the mount's check, used by
:mod:`nlosplan.simulators.fast.stability_cases` (which runs and caches them).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from nlosplan.simulators.presets import denali_scene

#: The mixed reflectance of the catalog: a retroreflective lobe and a Lambertian base of equal albedo.
MIXED = {"albedo": 0.5, "diffuse_albedo": 0.5}


def _ok(out: dict) -> bool:
    return all(np.all(np.isfinite(np.asarray(v))) and np.all(np.asarray(v) >= 0) for v in out.values())


def mixed(scenes):
    """The same scenes with every object retroreflective 0.5 on a Lambertian base of 0.5 (:data:`MIXED`)."""
    return [sc.replace(objects=tuple(dataclasses.replace(o, **MIXED) for o in sc.objects)) for sc in scenes]


def mount_near_wall_scenes(heights):
    """DENALI A_8in (retroreflective 0.4 + Lambertian 0.3) with its mount and plate (0.8) in the signal, moved
    along the wall normal until the closest vertex of any of them is at each of ``heights`` (metres)."""
    base = denali_scene("A", "8in", 0, mount=True, mount_in_background=False, albedo=0.4, diffuse_albedo=0.3)
    wall = base.wall
    h0 = min(float(wall.signed_distance(o.world_vertices()).min()) for o in base.objects)
    out = []
    for h in heights:
        shift = (h - h0) * wall.normal
        objs = []
        for o in base.objects:
            m = np.array(o.to_world)
            m[:3, 3] += shift
            objs.append(o.moved_to(m))
        out.append(base.replace(objects=tuple(objs)))
    return out


def mount_near_wall_check(out: dict, heights) -> tuple[bool, str]:
    """Judge the parts of :func:`mount_near_wall_scenes`: finite, >= 0, <= the direct return, < 2x per step."""
    n = len(heights)
    obj = np.asarray(out["object"]).reshape(n, -1).sum(-1)
    direct = float(np.asarray(out["direct"]).reshape(n, -1).sum(-1).min())
    steps = [obj[i] / obj[i + 1] for i in range(n - 1)] if np.all(obj > 0) else [math.inf]
    ok = _ok(out) and bool(np.all(obj <= direct)) and all(0.5 <= r <= 2.0 for r in steps)
    mm = "/".join(f"{1000 * h:g}" for h in heights)
    return ok, ("DENALI A_8in (retroreflective 0.4 + Lambertian 0.3) with mount and plate (0.8) in the signal, "
                f"closest vertex {mm} mm from the wall: object part " + "/".join(f"{v:.3g}" for v in obj)
                + " counts (steps " + ", ".join(f"x{r:.2f}" for r in steps)
                + f"); all finite, >= 0, <= direct {direct:.3g}")
