"""Scene presets: the DENALI capture rig and a parametric corner.

- :func:`denali_scene` — one DENALI capture (object, size, gantry position,
  lights) in the rig's calibrated world frame, with its packaged meshes;
  :func:`scene_at` the same with the gantry at any (x, y) mm. The rig's facts
  (objects, sizes, poses, labels) are :mod:`nlosplan.denali`'s.
- :func:`corner_scene` — a generic LiDAR / relay wall / hidden object corner
  for studies that vary the geometry.
"""

from nlosplan.simulators.presets.corner import corner_scene
from nlosplan.simulators.presets.denali import MOUNT_ALBEDO, denali_scene, mount_mesh, object_mesh, plate_mesh, rig, scene_at

__all__ = ["MOUNT_ALBEDO", "corner_scene", "denali_scene", "mount_mesh", "object_mesh", "plate_mesh", "rig", "scene_at"]
