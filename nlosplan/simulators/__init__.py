"""Scenes and light transport.

This room currently holds the flat-wall scene (first bounce of the flash off
a Lambertian wall), the scene of the ``nlosplan simulate`` default job and of
the time-base calibration. The three-bounce NLOS transport builds on it.
"""

from nlosplan.simulators.wall import WallScene, simulate_wall, wall_arrivals

__all__ = ["WallScene", "simulate_wall", "wall_arrivals"]
