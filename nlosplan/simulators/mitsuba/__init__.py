"""The Mitsuba 3 + mitransient digital twin (the ``mitsuba`` backend).

Importing this package does not import Mitsuba: that happens on the first
render (:func:`~nlosplan.simulators.mitsuba.env.load`).
"""

from nlosplan.simulators.mitsuba.fidelity import TWIN_LEVELS, TwinFidelity, resolve_twin_fidelity
from nlosplan.simulators.mitsuba.simulator import ILLUMINATIONS, TwinSimulator, spot_point

__all__ = ["ILLUMINATIONS", "TWIN_LEVELS", "TwinFidelity", "TwinSimulator", "resolve_twin_fidelity", "spot_point"]
