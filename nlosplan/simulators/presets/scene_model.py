"""The scene model a sensor's calibration comes with, and the tool's default sensor.

A sensor calibrated on DENALI's Table 2 (``nlosplan calibrate --stats``:
the presets ``denali-tmf8828-3x3`` and ``-8x8``) was fitted *together with*
scene parameters: the objects' retroreflective albedo, a diffuse base and
the object mount in the signal (:data:`~nlosplan.sensor_models.presets_denali.DENALI_SCENE_FIT`).
Its photon scale is only right with that scene: a DENALI scene simulated
with such a sensor takes those :func:`~nlosplan.simulators.presets.denali.denali_scene`
keywords unless the caller gives its own. Any other sensor keeps the
scene's own defaults (albedo 0.5, no diffuse base, no mount).

:data:`DEFAULT_SENSOR` is the sensor model of ``design``, ``dataset
build``, ``simulate --scene denali`` and the rig emulators when none is
given: DENALI's unit as calibrated on the real Table 2 (its real floor of
~10³ counts per bin included), not the datasheet's generic TMF8828.

Examples
--------
>>> scene_model("denali-tmf8828-3x3")
'denali-tmf8828-3x3'
>>> scene_options("denali-tmf8828-3x3")["mount"]
True
>>> scene_options(scene_model("tmf8828-3x3-short"))
{}
"""

from __future__ import annotations

__all__ = ["DEFAULT_SENSOR", "DEFAULT_SENSOR_8X8", "CALIBRATED_SCENE_MODELS", "scene_model", "scene_options",
           "describe_scene_options", "session_floor_sd"]

#: The sensor model used when none is given (DENALI's unit, calibrated on Table 2).
DEFAULT_SENSOR = "denali-tmf8828-3x3"
#: Its 8x8 mode (DENALI's 8x8 captures: the 3x3 fit's per-iteration rates).
DEFAULT_SENSOR_8X8 = "denali-tmf8828-8x8"
#: Presets whose calibration fitted scene parameters with them.
CALIBRATED_SCENE_MODELS = ("denali-tmf8828-3x3", "denali-tmf8828-8x8")


def scene_model(spec) -> str:
    """The calibrated scene model a sensor comes with: its DENALI preset's name, or ``""`` (none).

    Parameters
    ----------
    spec : str or SensorConfig
        A preset name, a sensor file (``base = "denali-tmf8828-3x3"`` refines the preset and keeps its
        scene model) or a :class:`~nlosplan.sensor_models.SensorConfig` (only an unmodified preset).
    """
    from nlosplan.sensor_models.presets import sensor_base

    base = sensor_base(spec)
    return base if base in CALIBRATED_SCENE_MODELS else ""


def scene_options(model: str) -> dict:
    """The :func:`denali_scene` keywords of a scene model (``""``: none, the scene's own defaults).

    Returns
    -------
    dict
        ``albedo``, ``diffuse_albedo``, ``mount``, ``mount_albedo``, ``mount_in_background`` of the Table-2 fit.
    """
    if not model:
        return {}
    if model not in CALIBRATED_SCENE_MODELS:
        from nlosplan.errors import UserError

        raise UserError(f"unknown scene model {model!r}; allowed: {', '.join(CALIBRATED_SCENE_MODELS)} or none")
    from nlosplan.sensor_models.presets_denali import DENALI_SCENE_FIT

    return dict(DENALI_SCENE_FIT)


def session_floor_sd(model: str) -> float:
    """How much the floor moves from one capture session to the next (standard deviation, fraction of the floor).

    A DENALI scene model: :data:`~nlosplan.sensor_models.presets_denali.DENALI_SESSION_FLOOR_SD` (1.73 %, from the
    Table-2 fit's background offsets); none (``""``): 0, every session has the sensor's floor.
    """
    if not model:
        return 0.0
    scene_options(model)   # an unknown model is refused there
    from nlosplan.sensor_models.presets_denali import DENALI_SESSION_FLOOR_SD

    return float(DENALI_SESSION_FLOOR_SD)


def describe_scene_options(options: dict) -> str:
    """One line a person reads: ``retro albedo 0.367, diffuse base 0.2, mount in the signal (albedo 0.8)``."""
    if not options:
        return "the scene's defaults (retro albedo 0.5, no diffuse base, no mount)"
    parts = []
    if "albedo" in options:
        parts.append(f"retro albedo {options['albedo']:.3g}")
    if "diffuse_albedo" in options:
        parts.append(f"diffuse base {options['diffuse_albedo']:.3g}")
    if options.get("mount"):
        where = "background" if options.get("mount_in_background", True) else "signal"
        parts.append(f"mount in the {where} (albedo {options.get('mount_albedo', 0.8):.3g})")
    elif "mount" in options:
        parts.append("no mount")
    return ", ".join(parts)
