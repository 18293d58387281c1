"""nlosplan: sensor-design and experiment planning for flash-LiDAR NLOS imaging.

The public surface lives in the rooms (subpackages):

- :mod:`nlosplan.sensor_models` -- sensor configurations, presets, zone
  geometry and exact histogram formation.
- :mod:`nlosplan.simulators` -- scenes and light transport.
- :mod:`nlosplan.reports` -- plots and report assembly.

Heavy optional dependencies (mitsuba, torch, dask) are imported only by the
code paths that use them.
"""

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("nlosplan")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
