"""The rig: serial drivers, pty emulators, capture plans and the executor that runs them.

- Drivers over pyserial (a port name, a pyserial URL, or an open serial
  object): :class:`TMF8828` (ams Arduino firmware, DENALI's start sequences,
  frame assembly) and two gantries with one interface
  (:mod:`.gantry`): :class:`Grbl` (GRBL 1.1, by the real firmware's rules:
  machine space, work offset, alarm lock) and :class:`TelemetrixGantry`
  (Telemetrix4Arduino steppers, DENALI's own rig); :mod:`.lights`.
- Emulators on pseudo-terminals that speak the same bytes
  (:mod:`nlosplan.hardware.emulators`), with fault injection.
- Plans are generators of small commands (:mod:`.commands`, :mod:`.plans`),
  run by :mod:`.executor` on the rig, on the emulators, or dry.
"""

from nlosplan.hardware.commands import Capture, CaptureResult, Checkpoint, Move, SetLights
from nlosplan.hardware.gantry import GantryPosition, WrongFirmware
from nlosplan.hardware.grbl import Grbl, GrblAlarm, GrblError, LimitError
from nlosplan.hardware.telemetrix import TelemetrixError, TelemetrixGantry
from nlosplan.hardware.telemetrix_config import TelemetrixConfig
from nlosplan.hardware.tmf8828 import TMF8828, SensorError
from nlosplan.hardware.tmf8828_protocol import Frame, FrameAssembler, RangeMode, ZoneMode

__all__ = ["Capture", "CaptureResult", "Checkpoint", "Frame", "FrameAssembler", "GantryPosition", "Grbl", "GrblAlarm",
           "GrblError", "LimitError", "Move", "RangeMode", "SensorError", "SetLights", "TMF8828", "TelemetrixConfig",
           "TelemetrixError", "TelemetrixGantry", "WrongFirmware", "ZoneMode"]
