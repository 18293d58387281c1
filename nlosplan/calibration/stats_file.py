"""Statistics files: published summary statistics of processed real captures (``calibrate --stats``/``--score``).

A statistics file (TOML, or the same tables as a JSON object) holds rows of
four statistics (total, centroid, spread, skew; each ``[mean, sem]``) per
condition, the processing that produced them (per zone mode), the targets a
model must meet, the scales of the fit's residuals, the protocol nuisances the
fit may use (with priors) and extra level constraints. The DENALI Table 2 file
ships as package data (:func:`shipped_stats`). Format: docs/calibration.md.

Every check fails with one line naming the field (``UserError``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from nlosplan.errors import UserError, check_keys

STATISTICS = ("total", "centroid", "spread", "skew")
LIGHTS = ("on", "off")
SIZES = ("4in", "8in")
ZONE_MODES = ("3x3", "8x8")
REPEATS = ("mean", "single")
LEVEL_STATISTICS = ("mean_count", "mean_log1p")
#: Nuisances the forward model knows (name -> allowed ``per``).
NUISANCES = {"background_offset": ("light",), "early_residual_counts": ("all",),
             "early_residual_decay_bins": ("all",)}
TARGET_KEYS = ("total_rel", "centroid_bins", "spread_rel", "skew", "ratio_rel")
SCALE_KEYS = ("total_rel", "centroid_bins", "spread_rel", "skew", "level_mean_rel", "level_log_mean")
SHIPPED = "denali_table2.toml"
#: The word that names the shipped file on the command line.
SHIPPED_NAME = "denali-table2"


@dataclass(frozen=True)
class Processing:
    """How one zone mode's histograms were processed before the statistics.

    ``zone`` is the (row, col) index of DENALI's (H, W) array; ``repeats``
    ``"mean"`` averages ``n_repeats`` captures and as many backgrounds;
    bins ``< crop_below_bin`` are zeroed and the difference clipped at ``clip_min``.
    """

    zone: tuple[int, int]
    repeats: str
    n_repeats: int
    background: str
    background_size: str
    crop_below_bin: int
    clip_min: float


@dataclass(frozen=True)
class Row:
    """One condition's statistics: ``values[s] = (mean, sem)`` for s in :data:`STATISTICS`."""

    zones: str
    light: str
    size: str
    values: dict

    @property
    def key(self) -> str:
        """``"<zones> <light> <size>"``, the name ratios use."""
        return f"{self.zones} {self.light} {self.size}"


@dataclass(frozen=True)
class Ratio:
    """``total(numerator) / total(denominator)``; its real value comes from the rows."""

    name: str
    numerator: str
    denominator: str


@dataclass(frozen=True)
class Nuisance:
    """A protocol nuisance: fitted once per value of ``per``, with a Gaussian prior and bounds."""

    name: str
    per: str
    prior: tuple[float, float]
    bounds: tuple[float, float]
    unit: str = ""


@dataclass(frozen=True)
class Level:
    """A raw-level constraint of one zone mode's processing zone (e.g. a checkpoint's mean count)."""

    name: str
    zones: str
    statistic: str
    value: float


@dataclass(frozen=True)
class StatsFile:
    """A parsed statistics file (see the module docstring)."""

    source: dict
    processing: dict          # zone mode -> Processing
    targets: dict
    fit_scales: dict
    nuisances: dict           # name -> Nuisance
    levels: tuple
    rows: tuple
    ratios: tuple
    path: str = field(default="", compare=False)

    def rows_for(self, zones: str) -> tuple:
        """The rows of one zone mode."""
        return tuple(r for r in self.rows if r.zones == zones)

    def row(self, key: str) -> Row:
        """The row named ``"<zones> <light> <size>"``."""
        for r in self.rows:
            if r.key == key:
                return r
        raise KeyError(key)

    def real_ratio(self, ratio: Ratio) -> float:
        """The ratio of the rows' real totals."""
        return self.row(ratio.numerator).values["total"][0] / self.row(ratio.denominator).values["total"][0]


def _num(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise UserError(f"{where} must be a number, got {v!r}")
    return float(v)


def _pair(v, where: str) -> tuple[float, float]:
    if not isinstance(v, list) or len(v) != 2:
        raise UserError(f"{where} must be [mean, sem] (two numbers), got {v!r}")
    return _num(v[0], where), _num(v[1], where)


def _table(data: dict, key: str, where: str) -> dict:
    if key not in data:
        raise UserError(f"{where}: missing field {key}")
    v = data[key]
    if not isinstance(v, dict):
        raise UserError(f"{where}: field {key} must be a table, got {type(v).__name__}")
    return v


def _choice(v, allowed, where: str) -> str:
    if v not in allowed:
        raise UserError(f"{where} is {v!r}; allowed: {', '.join(allowed)}")
    return v


def _require(d: dict, keys, where: str) -> None:
    check_keys(d, keys, "field(s)", prefix=f"{where}: ")
    for k in keys:
        if k not in d:
            raise UserError(f"{where}: missing field {k}")


def _processing(d: dict, where: str) -> Processing:
    _require(d, ("zone", "repeats", "n_repeats", "background", "background_size", "crop_below_bin", "clip_min"),
             where)
    z = d["zone"]
    if not (isinstance(z, list) and len(z) == 2 and all(isinstance(i, int) and not isinstance(i, bool) and i >= 0
                                                         for i in z)):
        raise UserError(f"{where}.zone must be [row, col] (two integers >= 0), got {z!r}")
    n = d["n_repeats"]
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise UserError(f"{where}.n_repeats must be an integer >= 1, got {n!r}")
    crop = d["crop_below_bin"]
    if not isinstance(crop, int) or isinstance(crop, bool) or crop < 0:
        raise UserError(f"{where}.crop_below_bin must be an integer >= 0, got {crop!r}")
    if not isinstance(d["background"], str):
        raise UserError(f"{where}.background must be a string, got {d['background']!r}")
    return Processing(zone=(z[0], z[1]), repeats=_choice(d["repeats"], REPEATS, f"{where}.repeats"), n_repeats=n,
                      background=d["background"],
                      background_size=_choice(d["background_size"], SIZES, f"{where}.background_size"),
                      crop_below_bin=crop, clip_min=_num(d["clip_min"], f"{where}.clip_min"))


def parse_stats(data: dict, path: str = "") -> StatsFile:
    """Validate the tables of a statistics file (see :func:`load_stats`)."""
    w = path or "statistics file"
    if not isinstance(data, dict):
        raise UserError(f"{w}: a statistics file is a table (TOML) or a JSON object")
    top = ("source", "processing", "targets", "fit_scales", "nuisances", "levels", "rows", "ratios")
    check_keys(data, top, "field(s)", prefix=f"{w}: ")
    source = _table(data, "source", w)
    if not all(isinstance(v, str) for v in source.values()):
        raise UserError(f"{w}: every field of source must be a string")
    proc_t = _table(data, "processing", w)
    check_keys(proc_t, ZONE_MODES, "zone mode(s)", prefix=f"{w}: ", suffix=" in processing")
    processing = {m: _processing(p if isinstance(p, dict) else {}, f"processing.{m}") for m, p in proc_t.items()}
    targets = _table(data, "targets", w)
    _require(targets, TARGET_KEYS, "targets")
    if targets["skew"] != "sign":
        raise UserError(f"targets.skew is {targets['skew']!r}; allowed: sign")
    targets = {k: (v if k == "skew" else _num(v, f"targets.{k}")) for k, v in targets.items()}
    scales = _table(data, "fit_scales", w)
    _require(scales, SCALE_KEYS, "fit_scales")
    scales = {k: _num(v, f"fit_scales.{k}") for k, v in scales.items()}
    if any(v <= 0 for v in scales.values()):
        raise UserError("fit_scales: every scale must be > 0")
    nuis = {}
    nt = data.get("nuisances", {})
    if not isinstance(nt, dict):
        raise UserError(f"{w}: field nuisances must be a table")
    check_keys(nt, tuple(NUISANCES), "nuisance(s)", prefix=f"{w}: ")
    for name, d in nt.items():
        wn = f"nuisances.{name}"
        if not isinstance(d, dict):
            raise UserError(f"{wn} must be a table")
        check_keys(d, ("per", "unit", "prior", "bounds"), "field(s)", prefix=f"{wn}: ")
        for k in ("per", "prior", "bounds"):
            if k not in d:
                raise UserError(f"{wn}: missing field {k}")
        prior, bounds = _pair(d["prior"], f"{wn}.prior"), _pair(d["bounds"], f"{wn}.bounds")
        if not bounds[0] < bounds[1] or prior[1] <= 0:
            raise UserError(f"{wn}: bounds must be [lo, hi] with lo < hi and the prior's std > 0")
        nuis[name] = Nuisance(name=name, per=_choice(d["per"], NUISANCES[name], f"{wn}.per"), prior=prior,
                              bounds=bounds, unit=str(d.get("unit", "")))
    levels = []
    for i, d in enumerate(data.get("levels", [])):
        wl = f"levels[{i}]"
        if not isinstance(d, dict):
            raise UserError(f"{wl} must be a table")
        _require(d, ("name", "zones", "statistic", "value"), wl)
        levels.append(Level(name=str(d["name"]), zones=_choice(d["zones"], tuple(processing), f"{wl}.zones"),
                            statistic=_choice(d["statistic"], LEVEL_STATISTICS, f"{wl}.statistic"),
                            value=_num(d["value"], f"{wl}.value")))
    rows_t = data.get("rows")
    if not isinstance(rows_t, list) or not rows_t:
        raise UserError(f"{w}: missing field rows (a list of [[rows]] tables)")
    rows, keys = [], set()
    for i, d in enumerate(rows_t):
        wr = f"rows[{i}]"
        if not isinstance(d, dict):
            raise UserError(f"{wr} must be a table")
        _require(d, ("zones", "light", "size") + STATISTICS, wr)
        row = Row(zones=_choice(d["zones"], tuple(processing), f"{wr}.zones"),
                  light=_choice(d["light"], LIGHTS, f"{wr}.light"), size=_choice(d["size"], SIZES, f"{wr}.size"),
                  values={s: _pair(d[s], f"{wr}.{s}") for s in STATISTICS})
        if row.key in keys:
            raise UserError(f"{wr}: a second row for {row.key}")
        keys.add(row.key)
        rows.append(row)
    ratios = []
    for i, d in enumerate(data.get("ratios", [])):
        wq = f"ratios[{i}]"
        if not isinstance(d, dict):
            raise UserError(f"{wq} must be a table")
        _require(d, ("name", "numerator", "denominator"), wq)
        for k in ("numerator", "denominator"):
            if d[k] not in keys:
                raise UserError(f"{wq}.{k} is {d[k]!r}; allowed: {', '.join(sorted(keys))}")
        ratios.append(Ratio(name=str(d["name"]), numerator=d["numerator"], denominator=d["denominator"]))
    return StatsFile(source=dict(source), processing=processing, targets=targets, fit_scales=scales, nuisances=nuis,
                     levels=tuple(levels), rows=tuple(rows), ratios=tuple(ratios), path=str(path))


def read_tables(path) -> dict:
    """The raw tables of a ``.toml`` or ``.json`` statistics file (one-line errors for unreadable files)."""
    from nlosplan.schema import loads, read_text

    p = Path(path)
    # a FIFO, binary, nesting too deep, a key twice: one line
    return loads(read_text(p, "statistics file"), "toml" if p.suffix == ".toml" else "json", f"statistics file {p}")


def load_stats(path) -> StatsFile:
    """Read and validate a statistics file (``.toml`` or ``.json``; :data:`SHIPPED_NAME` for the shipped one).

    Raises
    ------
    UserError
        Unreadable file, or a missing, extra or wrongly typed field (named in the message).
    """
    path = resolve_stats_path(path)
    return parse_stats(read_tables(path), str(path))


def shipped_path() -> Path:
    """Path of the packaged DENALI Table 2 statistics file."""
    return Path(str(resources.files("nlosplan.calibration") / "data" / SHIPPED))


def shipped_stats() -> StatsFile:
    """The packaged DENALI Table 2 statistics file, parsed."""
    return load_stats(shipped_path())


def resolve_stats_path(path):
    """``path`` itself, or the shipped file's path for the word :data:`SHIPPED_NAME`."""
    return shipped_path() if str(path) == SHIPPED_NAME else path
