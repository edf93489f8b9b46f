"""The geometry TOML file: strict reading (every problem named with its line) and atomic writing.

Format (metres, m/s)::

    name = "my site"            # optional
    [zone]                      # optional: overrides of the default zone, in the sensors' frame
    along = [2000.0, 48000.0]   #   along the first pair's baseline, from its receiver
    across = [-5000.0, 5000.0]  #   across it
    speed_max = 200.0           #   largest target speed
    altitude = [0.0, 12000.0]   #   optional: height band above the sensors' plane (3-D)
    [[pair]]                    # one table per bistatic pair, pair 0 first
    tx = [50000.0, 0.0]         # [x, y] (on the ground: z = 0) or [x, y, z]
    rx = [0.0, 0.0]
    name = "north"              # optional (every pair or none): the measurement file may say "north" for 0
    wavelength = 3.0            # optional (every pair or none): carrier wavelength in metres, c / f_c; the
                                # measurement file may then give each Doppler in Hz (column doppler_hz)

The problem is 3-D (states ``[x, y, z, vx, vy, vz]``) when a sensor has three
coordinates or the zone has an ``altitude`` band, 2-D otherwise: files with
neither read exactly as before.

Coordinates are TOML numbers (a string such as ``"50000"`` or a boolean is an
error, not a number); unknown keys are errors (a misspelt ``speed_max`` must
not be ignored silently).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

from fgdoppler._io import read_text_bounded
from fgdoppler.geodetic import GeodeticOrigin, check_geodetic

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["MAX_GEOMETRY_BYTES", "geometry_text", "read_geometry", "write_geometry"]

#: A geometry file larger than this is refused (it is a few lines of numbers).
MAX_GEOMETRY_BYTES = 1 << 20

_TOP = ("name", "zone", "geodetic", "pair")
_GEODETIC = ("origin", "positions")
_ZONE = ("along", "across", "speed_max", "altitude")
_PAIR = ("tx", "rx", "name", "wavelength")


def _line_of(text: str, key: str, occurrence: int = 0, table: str | None = None) -> int | None:
    """1-based line of the ``occurrence``-th ``key = ...`` (inside ``[table]``/``[[table]]`` if given)."""
    seen = 0
    current: str | None = None
    for i, line in enumerate(text.splitlines(), start=1):
        header = re.match(r"\s*\[\[?\s*([\w.-]+)\s*\]\]?", line)
        if header:
            current = header.group(1)
            continue
        if re.match(rf"\s*{re.escape(key)}\s*=", line) and (table is None or current == table):
            if seen == occurrence:
                return i
            seen += 1
    return None


def _where(path: Path, line: int | None) -> str:
    return f"{path}:{line}" if line else f"{path}"


def _check_keys(path: Path, text: str, table: dict[str, Any], allowed: tuple[str, ...], what: str,
                table_name: str | None = None) -> None:
    for key in table:
        if key not in allowed:
            raise ValueError(f"{_where(path, _line_of(text, key, table=table_name))}: unknown key {key!r} in "
                             f"{what} (expected {', '.join(allowed)})")


def read_geometry(path: str | Path) -> Any:
    """Read and validate a geometry TOML file.

    Returns
    -------
    fgdoppler.geometry.Geometry

    Raises
    ------
    ValueError
        Naming the file (and the line where it can be found) and the problem:
        not valid TOML, not UTF-8, too large, no pairs, an unknown key, a
        coordinate that is not a finite number, Tx equal to Rx, an empty,
        inverted or non-finite zone, a zone far from every sensor.
    """
    from fgdoppler.geometry import BistaticPair, Geometry
    from fgdoppler.zone import ZoneLimits

    path = Path(path)
    text = read_text_bounded(path, MAX_GEOMETRY_BYTES, what="geometry file")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"at line (\d+)", str(exc))
        raise ValueError(f"{_where(path, int(m.group(1)) if m else None)}: not valid TOML: {exc}") from None
    _check_keys(path, text, doc, _TOP, "the geometry")
    raw = doc.get("pair")
    if not isinstance(raw, list) or not raw:
        raise ValueError(f"{path}: expected one or more [[pair]] tables with tx and rx")
    geodetic = _geodetic_table(path, text, doc)
    pairs: list[Any] = []  # BistaticPair, or (tx, rx) geodetic tuples to convert
    names: list[str] = []
    wavelengths: list[float] = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict):
            raise ValueError(f"{path}: pair {i} needs both tx and rx")
        _check_keys(path, text, item, _PAIR, f"pair {i}", "pair")  # first: a misspelt tx is named as such
        if "tx" not in item or "rx" not in item:
            raise ValueError(f"{path}: pair {i} needs both tx and rx")
        if geodetic is not None and geodetic[1] == "geodetic":  # converted once every sensor is read
            pairs.append(tuple(_geodetic_sensor(path, text, item, key, i) for key in ("tx", "rx")))
        else:
            try:
                pairs.append(BistaticPair(tx=item["tx"], rx=item["rx"]))
            except (ValueError, TypeError) as exc:
                raise ValueError(f"{_where(path, _line_of(text, 'tx', i, 'pair'))}: pair {i}: {exc}") from None
        if "name" in item:
            if not isinstance(item["name"], str):
                raise ValueError(f"{_where(path, _line_of(text, 'name', len(names), 'pair'))}: pair {i}: name must be a "
                                 f"string, got {item['name']!r}")
            names.append(item["name"])
        if "wavelength" in item:
            value = item["wavelength"]
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise ValueError(f"{_where(path, _line_of(text, 'wavelength', len(wavelengths), 'pair'))}: pair {i}: "
                                 f"wavelength must be a number (metres), got {value!r}")
            wavelengths.append(value)
    _every_or_none(path, raw, "name", len(names), "name every pair or none")
    _every_or_none(path, raw, "wavelength", len(wavelengths), "give every pair's carrier wavelength or none")
    name = doc.get("name", "")
    if not isinstance(name, str):
        raise ValueError(f"{_where(path, _line_of(text, 'name'))}: name must be a string, got {name!r}")
    zone = doc.get("zone", {})
    if not isinstance(zone, dict):
        raise ValueError(f"{_where(path, _line_of(text, 'zone'))}: zone must be a table [zone]")
    _check_keys(path, text, zone, _ZONE, "[zone]", "zone")
    origin = None
    if geodetic is not None:
        pairs, origin = _from_geodetic(pairs, geodetic)
    try:
        limits = ZoneLimits(**zone)
        geometry = Geometry(pairs=tuple(pairs), name=name, zone_limits=limits, pair_names=tuple(names),
                            wavelengths=tuple(wavelengths), geodetic_origin=origin)
        geometry.check_zone()
    except ValueError as exc:
        raise ValueError(f"{_where(path, _error_line(text, str(exc)))}: {exc}") from None
    return geometry


def _every_or_none(path: Path, raw: list[Any], key: str, given: int, rule: str) -> None:
    """Refuse a key some pairs give and others do not, naming the first pair without it."""
    if given and given != len(raw):
        missing = next(i for i, item in enumerate(raw) if key not in item)
        raise ValueError(f"{path}: pair {missing} has no {key} while {given} other pair(s) have one: {rule}")


def _geodetic_table(path: Path, text: str, doc: dict[str, Any]) -> tuple[tuple[float, ...] | None, str] | None:
    """The ``[geodetic]`` table's origin (``None``: pair 0's receiver) and how the pairs give their positions
    (``"geodetic"``: latitude, longitude(, height); ``"enu"``: metres east, north(, up) of the origin); ``None``
    without the table."""
    table = doc.get("geodetic")
    if table is None:
        return None
    if not isinstance(table, dict):
        raise ValueError(f"{_where(path, _line_of(text, 'geodetic'))}: geodetic must be a table [geodetic]")
    _check_keys(path, text, table, _GEODETIC, "[geodetic]", "geodetic")
    positions = table.get("positions", "geodetic")
    if positions not in ("geodetic", "enu"):
        raise ValueError(f"{_where(path, _line_of(text, 'positions', table='geodetic'))}: positions must be "
                         f"\"geodetic\" (latitude, longitude, height) or \"enu\" (metres east, north, up of the "
                         f"origin), got {positions!r}")
    if "origin" not in table:
        if positions == "enu":
            raise ValueError(f"{path}: [geodetic] positions = \"enu\" needs the origin they are measured from")
        return None, positions
    try:
        return check_geodetic(table["origin"], "origin"), positions
    except ValueError as exc:
        raise ValueError(f"{_where(path, _line_of(text, 'origin', table='geodetic'))}: {exc}") from None


def _geodetic_sensor(path: Path, text: str, item: dict[str, Any], key: str, i: int) -> tuple[float, ...]:
    """Pair ``i``'s ``key`` (tx or rx) as latitude, longitude(, height), checked; an error names its own line."""
    try:
        return check_geodetic(item[key], key)
    except ValueError as exc:
        raise ValueError(f"{_where(path, _line_of(text, key, i, 'pair'))}: pair {i}: {exc}") from None


def _from_geodetic(pairs: list[Any], geodetic: tuple[tuple[float, ...] | None, str]
                   ) -> tuple[list[Any], GeodeticOrigin]:
    """The pairs in the origin's east-north-up frame (positions given as ``"enu"`` are already) and the origin:
    2-D ``(east, north)`` where every sensor is given by latitude and longitude alone, else 3-D with heights
    0 where none is given (:mod:`fgdoppler.geodetic`)."""
    from fgdoppler.geometry import BistaticPair

    given, positions = geodetic
    if positions == "enu":
        assert given is not None  # _geodetic_table requires the origin with "enu"
        return pairs, GeodeticOrigin(latitude=given[0], longitude=given[1], height=given[2] if len(given) == 3 else 0.0)
    sensors = [v for pair in pairs for v in pair]
    at = given if given is not None else sensors[1]  # pair 0's receiver
    origin = GeodeticOrigin(latitude=at[0], longitude=at[1], height=at[2] if len(at) == 3 else 0.0)
    e, n, u = origin.to_local([v[0] for v in sensors], [v[1] for v in sensors],
                              [v[2] if len(v) == 3 else 0.0 for v in sensors])
    flat = all(len(v) == 2 for v in sensors)
    local = [(e[k], n[k]) if flat else (e[k], n[k], u[k]) for k in range(len(sensors))]
    return [BistaticPair(tx=local[2 * i], rx=local[2 * i + 1]) for i in range(len(pairs))], origin


def _error_line(text: str, message: str) -> int | None:
    """The line of the key a :class:`~fgdoppler.geometry.Geometry` error names, where it names one."""
    per_pair = re.match(r"pair (\d+)'s (name|wavelength)", message)
    if per_pair:
        return _line_of(text, per_pair.group(2), int(per_pair.group(1)), "pair")
    if "pair names" in message:
        return None
    key = next((k for k in _ZONE if k in message), None)
    return _line_of(text, key, table="zone") if key else None


def geometry_text(geometry: Any) -> str:
    """The geometry file's text; :func:`read_geometry` reads it back exactly."""
    import tomli_w

    doc: dict[str, object] = {}
    if geometry.name:
        doc["name"] = geometry.name
    if geometry.geodetic_origin is not None:  # the local positions, exactly as held, and what they are relative to
        doc["geodetic"] = {"origin": geometry.geodetic_origin.to_list(), "positions": "enu"}
    if not geometry.zone_limits.empty:
        doc["zone"] = geometry.zone_limits.to_dict()
    doc["pair"] = [{"tx": list(p.tx), "rx": list(p.rx),
                    **({"name": geometry.pair_names[i]} if geometry.pair_names else {}),
                    **({"wavelength": geometry.wavelengths[i]} if geometry.wavelengths else {})}
                   for i, p in enumerate(geometry.pairs)]
    return _NUMBER_ARRAY.sub(_one_line, str(tomli_w.dumps(doc)))


#: An array of numbers as tomli-w writes it, one element a line (``[\n    0.0,\n    1.5,\n]``).
_NUMBER_ARRAY = re.compile(r"\[\n((?:[ ]+[-+0-9.eE]+(?:inf|nan)?,\n)+)\]")


def _one_line(match: re.Match[str]) -> str:
    """The array of ``match`` on one line, as the documentation shows it (``[0.0, 1.5]``)."""
    return "[" + ", ".join(v.strip().rstrip(",") for v in match.group(1).splitlines()) + "]"


def write_geometry(geometry: Any, path: str | Path) -> None:
    """Write :func:`geometry_text` atomically (temporary file, then rename)."""
    from fgdoppler._io import atomic_write_text

    atomic_write_text(Path(path), geometry_text(geometry))
