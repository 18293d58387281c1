"""The parameter uncertainty of a calibrated sensor: the ``X.uncertainty.json`` beside a sensor file ``X.toml``.

Written by ``nlosplan calibrate`` beside the calibrated sensor it refines
(or shipped with a preset, :func:`nlosplan.sensor_models.presets.preset_uncertainty`),
read by the design planner's worlds (:mod:`nlosplan.planner.design.worlds`),
which draw plausible sensors from it. The format::

    {"sensor": "<preset or file it refines>",
     "parameters": {"<SensorConfig field>": {"value": v, "std": s, "lo": l, "hi": h}, ...},
     "samples": [{"<field>": v, ...}, ...]}

``samples`` (bootstrap refits or posterior draws) may be empty; worlds draw
from them when present, else from independent normals ``N(value, std)``
clipped to ``[lo, hi]``. Every field must be a numeric
:class:`~nlosplan.sensor_models.SensorConfig` field with finite values,
``std >= 0`` and ``lo <= value <= hi``, each a valid value of that field.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig

__all__ = ["NUMERIC_FIELDS", "validate_uncertainty", "load_uncertainty", "uncertainty_path", "uncertainty_for"]

#: SensorConfig fields that hold one number (what an uncertainty or a world may vary).
NUMERIC_FIELDS: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(SensorConfig)
    if isinstance(f.default, (int, float)) and not isinstance(f.default, bool))


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise UserError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _field(name, where: str) -> str:
    if name not in NUMERIC_FIELDS:
        raise UserError(f"{where}: {name!r} is not a numeric sensor parameter; allowed: {', '.join(NUMERIC_FIELDS)}")
    return name


def _valid_value(name: str, v: float, where: str) -> None:
    try:
        SensorConfig().replace(**{name: int(v) if isinstance(getattr(SensorConfig(), name), int) else v})
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None


def validate_uncertainty(data, source: str = "uncertainty") -> dict:
    """Check a parameter-uncertainty dict (see the module notes) and return it with floats.

    Raises
    ------
    UserError
        One line naming the first bad field (``SOURCE: parameters.photon_scale.std ...``).
    """
    if not isinstance(data, dict):
        raise UserError(f"{source}: must be a JSON object with sensor, parameters and samples")
    unknown = sorted(set(data) - {"sensor", "parameters", "samples"})
    if unknown:
        raise UserError(f"{source}: unknown key(s) {', '.join(unknown)}; allowed: sensor, parameters, samples")
    if not isinstance(data.get("sensor"), str) or not data["sensor"]:
        raise UserError(f"{source}: sensor must name the preset or file the calibration refines")
    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        raise UserError(f"{source}: parameters must be a non-empty object of sensor fields")
    out = {}
    for name, p in params.items():
        where = f"{source}: parameters.{name}"
        _field(name, f"{source}: parameters")
        if not isinstance(p, dict) or set(p) != {"value", "std", "lo", "hi"}:
            raise UserError(f"{where} must hold exactly value, std, lo and hi")
        v = {k: _number(p[k], f"{where}.{k}") for k in ("value", "std", "lo", "hi")}
        if v["std"] < 0:
            raise UserError(f"{where}.std must be >= 0, got {v['std']:g}")
        if not v["lo"] <= v["value"] <= v["hi"]:
            raise UserError(f"{where}: needs lo <= value <= hi, got {v['lo']:g} <= {v['value']:g} <= {v['hi']:g}")
        for k in ("lo", "hi"):
            _valid_value(name, v[k], f"{where}.{k}")
        out[name] = v
    samples = data.get("samples", [])
    if not isinstance(samples, list):
        raise UserError(f"{source}: samples must be a list of objects (possibly empty)")
    clean = []
    for i, s in enumerate(samples):
        if not isinstance(s, dict) or not s:
            raise UserError(f"{source}: samples[{i}] must be an object of sensor fields")
        row = {}
        for name, value in s.items():
            if name not in out:
                raise UserError(f"{source}: samples[{i}].{name} is not among the parameters ({', '.join(out)})")
            row[name] = _number(value, f"{source}: samples[{i}].{name}")
            _valid_value(name, row[name], f"{source}: samples[{i}].{name}")
        clean.append(row)
    return {"sensor": data["sensor"], "parameters": out, "samples": clean}


def load_uncertainty(path) -> dict:
    """Read and validate an ``X.uncertainty.json`` file."""
    from nlosplan.schema import loads, read_text

    p = Path(path)
    data = loads(read_text(p, "uncertainty file"), "json", f"uncertainty file {p}")
    return validate_uncertainty(data, str(p))


def uncertainty_path(sensor_file) -> Path:
    """``X.uncertainty.json`` beside the sensor file ``X.toml`` (or ``X.json``)."""
    p = Path(sensor_file)
    return p.with_name(p.stem + ".uncertainty.json")


def uncertainty_for(spec) -> tuple[dict | None, str]:
    """The uncertainty of a sensor given as a preset name or file, and where it came from.

    A sensor file ``X.toml`` has the one beside it (``X.uncertainty.json``) if
    present; a preset has :func:`~nlosplan.sensor_models.presets.preset_uncertainty`'s.
    Returns ``(None, reason)`` when there is none.
    """
    from nlosplan.sensor_models.presets import preset_uncertainty

    spec = str(spec)
    if spec.endswith((".toml", ".json")):
        beside = uncertainty_path(spec)
        if beside.exists():
            return load_uncertainty(beside), str(beside)
        return None, f"no {beside.name} beside {spec}"
    data = preset_uncertainty(spec)
    if data is None:
        return None, f"the preset {spec} ships no parameter uncertainty"
    return validate_uncertainty(data, f"preset {spec}"), f"preset {spec}"
