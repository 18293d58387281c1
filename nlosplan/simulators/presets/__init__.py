"""Scene presets: the DENALI capture rig and a parametric corner.

- :func:`denali_scene` — one DENALI capture (object, size, gantry position,
  lights) in the rig's calibrated world frame, with its packaged meshes.
- :func:`corner_scene` — a generic LiDAR / relay wall / hidden object corner
  for studies that vary the geometry.
"""

from nlosplan.simulators.presets.denali import (
    CLASS_GROUPS,
    DENALI_OBJECTS,
    N_POSITIONS,
    SIZES,
    class_group,
    denali_scene,
    mount_mesh,
    object_mesh,
    object_pose,
    plate_mesh,
    plate_pose,
    positions_xy,
    rig,
)
from nlosplan.simulators.presets.corner import corner_scene

__all__ = [
    "CLASS_GROUPS",
    "DENALI_OBJECTS",
    "N_POSITIONS",
    "SIZES",
    "class_group",
    "corner_scene",
    "denali_scene",
    "mount_mesh",
    "object_mesh",
    "object_pose",
    "plate_mesh",
    "plate_pose",
    "positions_xy",
    "rig",
]
