"""Tables pfjax writes: one Parquet writer, and the unit and meaning of every column it knows.

Every Parquet file pfjax writes goes through :func:`write_parquet` (or, streamed chunk by chunk,
:func:`schema_with_units`): each column carries field metadata ``unit`` and ``description``
(from :data:`COLUMNS`, or the caller's), and the file carries the provenance record
(:func:`pfjax.provenance.parquet_metadata`). Read them back with
``pyarrow.parquet.read_schema(path).field(name).metadata`` or :func:`units`.

Naming: SI units unless the name ends in a unit suffix (``_deg``, ``_rad`` where an angle could be
mistaken for degrees, ``_hz``, ``_m``/``_s`` where the quantity could be mistaken for another).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # imported where used, so that the unit table (COLUMNS) costs no pandas or Arrow import
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

#: column -> (unit, description). Units: "1" dimensionless, "" text or code.
COLUMNS: dict[str, tuple[str, str]] = {
    # a study's run table: identity
    "path": ("", "path label"),
    "controller": ("", "controller name"),
    "run": ("", "run index (the random stream of the run)"),
    "config_sha256": ("", "SHA-256 of the study's config (pfjax.provenance.config_hash)"),
    # sampled quantities
    "speed": ("m/s", "rear-axle speed (st, std: the reference of the centre of mass's speed loop)"),
    "L": ("m", "wheelbase"),
    "delta_max_deg": ("deg", "steering limit"),
    "beta_r_deg": ("deg", "declared rear slip angle (constant part); NaN on st and std (slip from the tyres)"),
    "beta_f_deg": ("deg", "declared front slip angle (constant part); NaN on st and std (slip from the tyres)"),
    "step_time_s": ("s", "time of the slip step"),
    "step_r_deg": ("deg", "rear slip step"),
    "step_f_deg": ("deg", "front slip step"),
    "amp_r_deg": ("deg", "rear slip sinusoid amplitude"),
    "amp_f_deg": ("deg", "front slip sinusoid amplitude"),
    "freq_hz": ("Hz", "slip sinusoid frequency"),
    "ou_sigma_deg": ("deg", "Ornstein-Uhlenbeck slip: stationary standard deviation"),
    "ou_tau_s": ("s", "Ornstein-Uhlenbeck slip: time constant"),
    "start_along_m": ("m", "start, along the path from its nominal start"),
    "lateral_offset": ("m", "start offset left of the path"),
    "heading_error_deg": ("deg", "start heading error"),
    "radius": ("m", "circle radius"),
    "mu": ("1", "tyre-road friction coefficient (vehicle.model = st)"),
    # metrics (pfjax.metrics.running)
    "iae": ("m s", "integral of |d| over the run"),
    "ise": ("m^2 s", "integral of d^2 over the run"),
    "itae": ("m s^2", "integral of t |d| over the run"),
    "max_abs_d": ("m", "largest |d|"),
    "steady_abs_d": ("m", "mean |d| over the steady window (the last steady_window s)"),
    "steady_abs_theta_e_rad": ("rad", "mean |heading error| over the steady window"),
    "settling_time": ("s", "time after which |d| stays within settle_band (NaN: never)"),
    "overshoot": ("m", "largest lateral error past the path, opposite to the initial one"),
    "steer_energy": ("rad^2 s", "integral of delta^2"),
    "steer_tv": ("rad", "total variation of the applied steering"),
    "sat_fraction": ("1", "fraction of the run with the command beyond the steering limit"),
    "late_max_abs_d": ("m", "largest |d| from the success window's start on; NaN for a run that failed before it"),
    "success": ("", "no failure and |d| <= success band from success.from_s on"),
    "status_code": ("", "run status code (pfjax.sim.status)"),
    "status": ("", "run status name: ok, nonfinite, diverged, singular, path_end"),
    "fail_time": ("s", "time of the first failure (NaN: none)"),
    # slip the ST model produced (pfjax.sim.dynamic.SlipMetrics; vehicle.model = st)
    "max_abs_beta_r_deg": (
        "deg",
        "st: largest |rear-axle slip| (kinematic model's convention); NaN for a run that failed at t = 0",
    ),
    "max_abs_beta_f_deg": (
        "deg",
        "st: largest |front-wheel slip| (kinematic model's convention); NaN for a run that failed at t = 0",
    ),
    "max_abs_beta_deg": ("deg", "st: largest |slip angle at the centre of mass|; NaN for a run that failed at t = 0"),
    "mean_abs_beta_r_deg": ("deg", "st: time-mean |rear-axle slip|; NaN for a run that failed at t = 0"),
    "mean_abs_beta_f_deg": ("deg", "st: time-mean |front-wheel slip|; NaN for a run that failed at t = 0"),
    "mean_abs_beta_deg": (
        "deg",
        "st: time-mean |slip angle at the centre of mass|; NaN for a run that failed at t = 0",
    ),
    # the margin sweep
    "amplitude_deg": ("deg", "slip amplitude A of the sweep"),
    "axis": ("", "slipping axle(s): rear, front or joint"),
    "n": ("runs", "runs"),
    "k": ("runs", "successful runs"),
}


#: The channels of the slip design's norms (:func:`pfjax.synthesis.slip_design_plant`; ``int d`` in
#: the integral designs): an H-infinity or H2 norm or bound is a number of these channels in SI units,
#: which differ, so it has no one unit. ``"H-infinity norm " + HINF_CHANNELS``.
_W = "w = [beta_r rad, beta_f rad, kappa 1/m]"
_Z_INF = "z_inf = [d m, theta_e rad(, int d m s in the integral designs)]"
HINF_CHANNELS = f"from {_W} to {_Z_INF} (SI units: no one unit)"
H2_CHANNELS = f"from {_W} to z_2 = [{_Z_INF}; delta rad] (SI units: no one unit)"


#: The base units a gain's unit is written in (:func:`unit_powers`): their powers of length and time.
_BASE_UNITS = {"m": (1, 0), "s": (0, 1), "rad": (0, 0), "1": (0, 0)}


#: A power of a base unit: an integer or a decimal, signed (``m^2``, ``s^-1``, ``m^0.5``).
_POWER = re.compile(r"[+-]?[0-9]+(\.[0-9]+)?")


def _product_powers(product: str) -> tuple[float, float] | None:
    """The powers of m and s of a product of base units (``"m s"``, ``"m^2"``, ``"(m s)"``: one pair
    of parentheses around the whole product at most); None if it is empty or has anything else."""
    text = product.strip()
    if text.startswith("(") and text.endswith(")"):
        text = text[1:-1]
    if not text.strip() or "(" in text or ")" in text:
        return None
    a = b = 0.0
    for token in text.split():
        base, hat, power = token.partition("^")
        if base not in _BASE_UNITS or (hat and not _POWER.fullmatch(power)):
            return None
        n = float(power) if hat else 1.0
        a, b = a + n * _BASE_UNITS[base][0], b + n * _BASE_UNITS[base][1]
    return a, b


def unit_powers(unit: str) -> tuple[float, float] | None:
    """The powers ``(a, b)`` of a unit ``m^a s^b`` written as a product of ``m``, ``s``, ``rad``
    and ``1`` with powers, over one such product (``rad/(m s)`` -> ``(-1, -1)``, ``1/m^2`` ->
    ``(-2, 0)``; ``rad`` and ``1`` are dimensionless); None for a unit written otherwise (an empty
    side of ``/``, unmatched parentheses, a power that is not a plain number). How a controller's
    gain units are written (:func:`pfjax.controllers.register` refuses others), and what the
    Froude scaling of a gain reads (:func:`pfjax.dynamic_study.arms.froude_exponent`)."""
    if not isinstance(unit, str) or unit.count("/") > 1:
        return None
    num, slash, den = unit.partition("/")
    top = _product_powers(num)
    bottom = _product_powers(den) if slash else (0.0, 0.0)
    if top is None or bottom is None:
        return None
    return top[0] - bottom[0], top[1] - bottom[1]


_PARKING_POSE = {"x0.x": "m", "x0.y": "m", "x0.theta_deg": "deg"}
#: The flags both parking commands take, by unit.
_PARKING_ARGUMENTS = {
    "x0": "m, m, deg",
    "k1": "1/m^2",
    "k2": "1/m",
    "speed": "m/s",
    "scan_period": "s",
    "front": "m",
    "horizon": "s",
}
#: The source's end error ``|x| + sqrt(y^2 + tan^2 theta)`` (m and the tangent's 1, as it defines it).
_PARKING_ERROR = "m (|x| + sqrt(y^2 + tan^2 theta), the source's measure)"
#: The unit of each number :func:`pfjax.parking.run` returns (``pfjax parking --json`` prints it with
#: them, :func:`pfjax.cli.records.units`; ``"arguments.*"``: the command's flags). Here, not in
#: :mod:`pfjax.parking`, so that the command line reads it without importing the simulator.
PARKING_RUN_UNITS: dict[str, Any] = {
    **_PARKING_POSE,
    "alpha_schedule": "1",
    "xs": "m",
    "a_f": "m",
    "time_s": "s",
    "switches": "direction switches (count)",
    "switch_log.*": {"t": "s", "x": "m", "y": "m", "theta_deg": "deg"},
    "final.*": {"x": "m", "y": "m", "theta_deg": "deg"},
    "error": _PARKING_ERROR,
    "distance_m": "m",
    "arguments.*": {**_PARKING_ARGUMENTS, "alpha_schedule": "1", "xs": "m"},
}
#: The search's fitness J = 1 / (t_e + w e): the inverse of a time (--weight w in s/m).
_PARKING_FITNESS = "1/s (J = 1/(t_e + --weight x error))"
#: The unit of each number :func:`pfjax.parking.search` returns (``pfjax parking-search --json``).
PARKING_SEARCH_UNITS: dict[str, Any] = {
    **_PARKING_POSE,
    "xs": "m",
    "alpha1": "1",
    "alpha2": "1",
    "fitness": _PARKING_FITNESS,
    "history_best_fitness": _PARKING_FITNESS,
    "history_mean_fitness": _PARKING_FITNESS,
    "time_s": "s",
    "switches": "direction switches (count)",
    "n_simulations": "runs (simulated)",
    "n": "levels per gene of the n x n x n grid",
    "bits": "1 (the chromosome's 24 bits, each 0 or 1)",
    "a_f": "m",
    "error": _PARKING_ERROR,
    "arguments.*": {
        **_PARKING_ARGUMENTS,
        "n": "levels per gene (count)",
        "seed": "1 (the random seed)",
        "generations": "GA generations (count)",
        "population": "GA individuals (count)",
        "weight": "s/m",
    },
}


#: The unit of each number :func:`pfjax.tracking.run` returns (``pfjax track --json`` prints it
#: with them, :func:`pfjax.cli.records.units`; the vehicle-tracking study's columns take their units
#: from it, :data:`pfjax.tracking.study.COLUMNS`). ``"<parent>.*"``: the units under ``<parent>`` by
#: name. "1": dimensionless. Here, not in :mod:`pfjax.tracking`, so that the command line reads it
#: without importing the simulator.
TRACK_UNITS: dict[str, Any] = {
    "f": "1 (travel direction: 1 forward, -1 backward)",
    "p": "1",
    "l": "m",
    "gamma_max_deg": "deg",
    "final_error_norm": "m",
    "final_phi_minus_pgamma": "rad",
    "max_abs_gamma_deg": "deg",
    "window_max_z": "m",
    "window_max_phi_err": "rad",
    "iae": "m s",
    "final_d": "m",
    "limit_fraction": "1",
    "min_abs_factor": "1",
    "lemma_p_bound": "1",
    "fail_time": "s",
    "tolerances.*": {"window_s": "s", "tol_z_m": "m", "tol_phi_rad": "rad"},
    "final.*": {"x": "m", "y": "m", "theta": "rad", "gamma": "rad"},
    "T": "s",
    "dt": "s",
    "arguments.*": {  # pfjax track's flags
        "p": "1",
        "l": "m",
        "gamma_max_deg": "deg",
        "speed": "m/s",
        "stop_and_go": "1",
        "wheelbase": "m",
        "k": "1/s",
        "v_max": "m/s",
        "omega_max_deg": "deg/s",
        "offset": "m, m",
        "heading_error_deg": "deg",
        "beta_r_deg": "deg",
        "beta_f_deg": "deg",
        "horizon": "s",
        "dt": "s",
    },
}


def units(path: str | Path) -> dict[str, dict[str, str]]:
    """``{column: {"unit": ..., "description": ...}}`` of a Parquet file pfjax wrote."""
    import pyarrow.parquet as pq

    out = {}
    for f in pq.read_schema(path):
        md = f.metadata or {}
        if b"unit" in md or b"description" in md:
            out[f.name] = {"unit": md.get(b"unit", b"").decode(), "description": md.get(b"description", b"").decode()}
    return out


def schema_with_units(schema, extra: dict[str, tuple[str, str]] | None = None, metadata: dict | None = None):
    """``schema`` with each known column's unit and description as field metadata (``extra``
    first, then :data:`COLUMNS`) and ``metadata`` added to the schema's key-value metadata."""
    import pyarrow as pa

    known = {**COLUMNS, **(extra or {})}
    fields = []
    for f in schema:
        if f.name in known:
            unit, desc = known[f.name]
            f = f.with_metadata({**(f.metadata or {}), b"unit": unit.encode(), b"description": desc.encode()})
        fields.append(f)
    md = {
        **(schema.metadata or {}),
        **{
            (k if isinstance(k, bytes) else str(k).encode()): (v if isinstance(v, bytes) else str(v).encode())
            for k, v in (metadata or {}).items()
        },
    }
    return pa.schema(fields, metadata=md)


def to_arrow(df, extra: dict[str, tuple[str, str]] | None = None, metadata: dict | None = None):
    """A pandas DataFrame as an Arrow table with units (:func:`schema_with_units`), no index."""
    import pyarrow as pa

    t = pa.Table.from_pandas(df.reset_index(drop=True), preserve_index=False)
    return t.cast(schema_with_units(t.schema, extra, metadata))


def write_parquet(
    df, path: str | Path, metadata: dict | None = None, *, units: dict[str, tuple[str, str]] | None = None
) -> None:
    """Write ``df`` (pandas) to ``path`` with column units and ``metadata``
    (:func:`pfjax.provenance.parquet_metadata`)."""
    import pyarrow.parquet as pq

    pq.write_table(to_arrow(df, units, metadata), path)


class ParquetAppender:
    """Tables appended to one Parquet file as they come, one row group each (memory: one table);
    the file's schema is the first table's, with units (:func:`schema_with_units`) and ``metadata``
    added. A context manager; with no table at all, an empty table that still carries ``metadata``
    is written."""

    def __init__(self, dest: Path, metadata: dict[bytes, bytes]):
        self.dest, self.metadata, self.rows = Path(dest), metadata, 0
        self._writer: pq.ParquetWriter | None = None

    def write(self, table: pa.Table | pd.DataFrame) -> None:
        import pandas as pd
        import pyarrow as pa
        import pyarrow.parquet as pq

        if isinstance(table, pd.DataFrame):
            table = pa.Table.from_pandas(table, preserve_index=False)
        if self._writer is None:
            schema = schema_with_units(table.schema, metadata=self.metadata)
            self._writer = pq.ParquetWriter(self.dest, schema)
        self._writer.write_table(table.cast(self._writer.schema))
        self.rows += table.num_rows

    def __enter__(self) -> ParquetAppender:
        return self

    def __exit__(self, *exc) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self._writer is not None:
            self._writer.close()
        elif exc[0] is None:
            pq.write_table(pa.table({}).replace_schema_metadata(self.metadata), self.dest)
