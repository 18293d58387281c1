"""Pty emulators of the rig's devices (the production drivers talk to them through real ptys)."""

from nlosplan.hardware.emulators.faults import GantryFaults, SensorFaults
from nlosplan.hardware.emulators.grbl import EmulatedGrbl
from nlosplan.hardware.emulators.telemetrix import EmulatedTelemetrix
from nlosplan.hardware.emulators.tmf8828 import EmulatedTMF8828

__all__ = ["EmulatedGrbl", "EmulatedTMF8828", "EmulatedTelemetrix", "GantryFaults", "SensorFaults"]
