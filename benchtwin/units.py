"""Units: parse quantities written with units ("7.1 um", "192.08 deg") into SI floats.

Scenario and bench files carry units in their values; inside the code everything is SI (m, rad,
s, kg, N) and dataset columns carry the unit in their names (``_um``, ``_arcsec``). This module is
the one place where unit symbols and conversion factors live.

Why not pint: the set of units a bench needs is small and fixed, the error messages must name the
file and key (see ``benchtwin.twin.scenario``), and a table we own can be checked at a glance.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

# Conversion constants (exact by definition).
DEG = math.pi / 180.0
ARCMIN = DEG / 60.0
ARCSEC = DEG / 3600.0  # = pi / 648000 rad (the same float)
ARCSEC_PER_RAD = 648000.0 / math.pi  # = 1 / ARCSEC (the same float)
UM = 1e-6
MM = 1e-3
NM = 1e-9

# unit symbol -> (factor to SI, dimension)
_UNITS: dict[str, tuple[float, str]] = {
    # length
    "m": (1.0, "length"),
    "mm": (MM, "length"),
    "um": (UM, "length"),
    "µm": (UM, "length"),
    "nm": (NM, "length"),
    # angle (radian is the SI coherent unit; kept as its own dimension to catch mistakes)
    "rad": (1.0, "angle"),
    "mrad": (1e-3, "angle"),
    "urad": (1e-6, "angle"),
    "µrad": (1e-6, "angle"),
    "deg": (DEG, "angle"),
    "arcmin": (ARCMIN, "angle"),
    "arcsec": (ARCSEC, "angle"),
    # time
    "s": (1.0, "time"),
    "ms": (1e-3, "time"),
    "us": (1e-6, "time"),
    "min": (60.0, "time"),
    "h": (3600.0, "time"),
    # mass
    "kg": (1.0, "mass"),
    "g": (1e-3, "mass"),
    # frequency / rotational speed
    "Hz": (1.0, "frequency"),
    "rpm": (1.0 / 60.0, "frequency"),
    "deg/s": (DEG, "angular_speed"),
    "rad/s": (1.0, "angular_speed"),
    # mechanics
    "N": (1.0, "force"),
    "N/m": (1.0, "stiffness"),
    "N/um": (1e6, "stiffness"),
    "N*s/m": (1.0, "damping"),
    "N*m": (1.0, "torque"),
    "N*m/rad": (1.0, "torsional_stiffness"),
    "kg*m": (1.0, "unbalance"),
    "g*mm": (1e-6, "unbalance"),
    "kg*m^2": (1.0, "inertia"),
    # air bearings (twin/air_bearing.py): gauge pressures, a porous restrictor's permeability
    "Pa": (1.0, "pressure"),
    "kPa": (1e3, "pressure"),
    "MPa": (1e6, "pressure"),
    "bar": (1e5, "pressure"),
    "m^2": (1.0, "area"),
    # drift rates
    "arcsec/s": (ARCSEC, "angular_speed"),
    "arcsec/h": (ARCSEC / 3600.0, "angular_speed"),
    "um/s": (UM, "speed"),
    "mm/s": (MM, "speed"),
    # thermal (twin/thermal.py): temperatures in °C (the scenario's "SI" for a temperature is °C:
    # the bench's models use differences and the papers' 20 °C reference), differences in K
    "degC": (1.0, "temperature"),
    "K": (1.0, "temperature_difference"),
    "mK": (1e-3, "temperature_difference"),
    "um/K": (UM, "length_per_kelvin"),
    "nm/K": (NM, "length_per_kelvin"),
    "arcsec/K": (ARCSEC, "angle_per_kelvin"),
    "ppm/K": (1e-6, "per_kelvin"),
    "per_K": (1.0, "per_kelvin"),
    # optics / sensor
    "um/px": (UM, "pixel_pitch"),
    "px": (1.0, "pixels"),
    "lx*s": (1.0, "exposure"),
    "e-": (1.0, "electrons"),
    "%": (0.01, "dimensionless"),
    "ppm": (1e-6, "dimensionless"),
    "": (1.0, "dimensionless"),
}

DIMENSIONS = frozenset(d for _, d in _UNITS.values())

# ASCII digits only: \d would also take other scripts' digits ("١٢ mm"), the one number grammar
# of benchtwin.schema (issue #13)
_NUMBER = r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*([^\s\d.+-][^\s]*)?\s*$")


class UnitError(ValueError):
    """A quantity string that cannot be parsed, or whose unit has the wrong dimension."""


@dataclass(frozen=True)
class Quantity:
    """A parsed quantity: ``si`` is the value in SI units of ``dimension``."""

    si: float
    dimension: str
    text: str


def units_of(dimension: str) -> list[str]:
    """The unit symbols accepted for a dimension (for error messages)."""
    return [u for u, (_, d) in _UNITS.items() if d == dimension and u]


def parse_quantity(value: str | int | float, dimension: str) -> float:
    """Parse ``value`` ("7.1 um", "0.39 arcsec", 3) to SI, checking it has ``dimension``.

    A bare number is accepted only for dimensionless quantities; for anything else the unit is
    required, so that "7.1" can never silently mean metres.

    >>> parse_quantity("7.1 um", "length")
    7.1e-06
    """
    if dimension not in DIMENSIONS:
        raise UnitError(f"unknown dimension {dimension!r}")
    if isinstance(value, bool):
        raise UnitError(f"expected a quantity of dimension {dimension}, got a boolean {value!r}")
    if isinstance(value, (int, float)):
        if dimension != "dimensionless":
            raise UnitError(
                f"expected a {dimension} with a unit (one of {', '.join(units_of(dimension))}), "
                f"got the bare number {value!r}"
            )
        try:
            return _finite(float(value), value)
        except OverflowError:  # an integer beyond a double
            raise UnitError(f"{value!r} is too large for a number") from None
    if not isinstance(value, str):
        raise UnitError(f"expected a string like '1.5 {units_of(dimension)[0] if units_of(dimension) else ''}', got {type(value).__name__}")
    m = _QUANTITY.match(value)
    if not m:
        raise UnitError(f"cannot read {value!r} as a number followed by a unit")
    number, unit = float(m.group(1)), m.group(2) or ""
    if not unit and dimension != "dimensionless":
        raise UnitError(f"expected a {dimension} with a unit (one of {', '.join(units_of(dimension))}), "
                        f"got the bare number {value!r}")
    if unit not in _UNITS:
        raise UnitError(f"unknown unit {unit!r} in {value!r}; known units for {dimension}: "
                        f"{', '.join(units_of(dimension)) or '(none: write a bare number)'}")
    factor, dim = _UNITS[unit]
    if dim != dimension:
        raise UnitError(
            f"{value!r} is a {dim}, expected a {dimension} "
            f"(one of {', '.join(units_of(dimension)) or 'a bare number'})"
        )
    return _finite(number * factor, value)


def _finite(x: float, original: object) -> float:
    if not math.isfinite(x):
        raise UnitError(f"{original!r} is not a finite number")
    return x


def format_quantity(si_value: float, unit: str) -> str:
    """Write an SI value back as a string in ``unit`` (inverse of ``parse_quantity``)."""
    factor, _ = _UNITS[unit]
    return f"{si_value / factor!r} {unit}".rstrip()


def wrap_deg(angle_deg: float) -> float:
    """An angle in degrees wrapped into [0, 360). ``x % 360.0`` alone returns 360.0 for a tiny
    negative x (e.g. −1e-15°: the exact result 360 − 1e-15 rounds to 360.0), which is outside the
    interval and flips at rounding level between BLAS kernels; that case maps to 0.0."""
    w = float(angle_deg) % 360.0
    return 0.0 if w >= 360.0 else w


def quantise(x: float, step: float) -> float:
    """Round ``x`` to a multiple of ``step`` (same unit), as an instrument's display does; a step whose
    inverse is an integer (0.01 µm, 0.005″) divides, so the value is the correctly rounded decimal
    (clean CSVs). ``step`` ≤ 0 or 0: no quantisation. Shared by the twin's instruments and ``acquire``."""
    if not step or step <= 0:
        return float(x)
    inv = 1.0 / step
    k = round(x / step)
    if abs(inv - round(inv)) < 1e-9 * inv:
        return k / round(inv)
    return k * step
