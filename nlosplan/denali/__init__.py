"""The DENALI capture rig as data (a low room: facts only, no light transport).

- :mod:`.rig` — the 30 objects and their class groups, the two sizes, the 100
  gantry positions; object poses per position (tag 1), DENALI's localization
  labels, the wall/table/camera placement of the rig; validation of object,
  size and position names.
- :mod:`.geometry` — the gantry in millimetres: the 10 x 10 snake grid and
  the object pose and label at any (x, y).
- ``data/`` — the packaged DENALI files (geometry JSON and 60 object meshes,
  MIT, see its README).

Scenes of the rig are built one room up, by
:func:`nlosplan.simulators.presets.denali.denali_scene` and
:func:`~nlosplan.simulators.presets.denali.scene_at`.
"""

from nlosplan.denali.geometry import GRID_N, PITCH_MM, TRAVEL_MM, grid_index, grid_mm, label_xy, object_pose_mm
from nlosplan.denali.rig import (
    ALIASES,
    CLASS_GROUPS,
    DENALI_OBJECTS,
    MOUNT_OFFSET,
    N_POSITIONS,
    SIZES,
    TABLE_SIZE,
    WALL_SIZE,
    WALL_TAG_DROP,
    WALL_TAG_MARGIN,
    camera_pose,
    check_object,
    check_position,
    check_size,
    class_group,
    data_dir,
    object_pose,
    plate_pose,
    object_poses,
    positions_xy,
    read_json,
    tag1_positions,
    tag_pose,
    tag_transform,
)

__all__ = [
    "ALIASES", "CLASS_GROUPS", "DENALI_OBJECTS", "GRID_N", "MOUNT_OFFSET", "N_POSITIONS", "PITCH_MM", "SIZES",
    "TABLE_SIZE", "TRAVEL_MM", "WALL_SIZE", "WALL_TAG_DROP", "WALL_TAG_MARGIN", "camera_pose", "check_object",
    "check_position", "check_size", "class_group", "data_dir", "grid_index", "grid_mm", "label_xy", "object_pose", "plate_pose",
    "object_pose_mm", "object_poses", "positions_xy", "read_json", "tag1_positions", "tag_pose", "tag_transform",
]
