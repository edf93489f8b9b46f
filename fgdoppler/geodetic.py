r"""Sensor positions given as latitude, longitude and height: the local east-north-up frame they are read into.

A geometry file may give every sensor as WGS84 geodetic coordinates
(:mod:`fgdoppler.geometry_file`, its ``[geodetic]`` table).  fgdoppler then
works, as always, in metres: in the *local east-north-up* (ENU) frame of an
origin :math:`(\varphi_0, \lambda_0, h_0)`, a rigid transform of the
Earth-centred frame (ECEF),

.. math::

    \begin{pmatrix} e \\ n \\ u \end{pmatrix} =
    \begin{pmatrix} -\sin\lambda_0 & \cos\lambda_0 & 0 \\
    -\sin\varphi_0\cos\lambda_0 & -\sin\varphi_0\sin\lambda_0 & \cos\varphi_0 \\
    \cos\varphi_0\cos\lambda_0 & \cos\varphi_0\sin\lambda_0 & \sin\varphi_0 \end{pmatrix}
    \left(\mathbf r(\varphi, \lambda, h) - \mathbf r(\varphi_0, \lambda_0, h_0)\right),

with :math:`\mathbf r(\varphi, \lambda, h) = ((N + h)\cos\varphi\cos\lambda,\ (N + h)\cos\varphi\sin\lambda,\
((1 - e^2) N + h)\sin\varphi)`, :math:`N = a / \sqrt{1 - e^2 \sin^2\varphi}` on the WGS84 ellipsoid.  Distances
and angles are those of the Earth-centred frame, so the bistatic Doppler is unchanged.  The conversions are
pymap3d's (``geodetic2enu``, ``enu2geodetic``).

In 2-D (every sensor given by latitude and longitude alone) the positions
are ``(e, n)``: the sensors' drop below the tangent plane through the
origin, about :math:`d^2 / 2R` (200 m at 50 km), is ignored as the 2-D model
ignores a target's altitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d
from numpy.typing import ArrayLike, NDArray

__all__ = ["HEIGHT_LIMIT", "GeodeticOrigin", "check_geodetic"]

#: Largest height (m) above or below the WGS84 ellipsoid a sensor or origin may be given (a satellite-borne
#: transmitter is out of scope; a larger value is almost certainly a unit slip).
HEIGHT_LIMIT = 1e5


def check_geodetic(value: object, what: str) -> tuple[float, ...]:
    """``value`` as ``(latitude, longitude)`` or ``(latitude, longitude, height)``: degrees, degrees, metres.

    Raises
    ------
    ValueError
        If it is not two or three finite numbers (a string or a boolean is
        not a number), a latitude outside [-90, 90], a longitude outside
        [-180, 360] or a height beyond :data:`HEIGHT_LIMIT`.
    """
    v: tuple[float, ...] = ()
    if isinstance(value, list | tuple) and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value):
        v = tuple(float(x) for x in value)
    if len(v) not in (2, 3) or not all(math.isfinite(x) for x in v):
        raise ValueError(f"{what} must be two or three finite numbers [latitude, longitude(, height)] in degrees, "
                         f"degrees and metres, got {value!r}")
    if not -90.0 <= v[0] <= 90.0:
        raise ValueError(f"{what}: latitude {v[0]:g} is outside [-90, 90] degrees (latitude first, then longitude)")
    if not -180.0 <= v[1] <= 360.0:
        raise ValueError(f"{what}: longitude {v[1]:g} is outside [-180, 360] degrees")
    if len(v) == 3 and abs(v[2]) > HEIGHT_LIMIT:
        raise ValueError(f"{what}: height {v[2]:g} m is beyond {HEIGHT_LIMIT:g} m of the ellipsoid (metres, not feet "
                         "or kilometres?)")
    return v


@dataclass(frozen=True, kw_only=True)
class GeodeticOrigin:
    """The origin of a local east-north-up frame: WGS84 latitude and longitude (degrees) and height (m).

    A geometry read from geodetic positions keeps it
    (:attr:`fgdoppler.geometry.Geometry.geodetic_origin`): its ``x, y, z``
    are then east, north and up in metres from this point, and every
    estimate can be given as latitude, longitude and height again
    (:meth:`to_geodetic`).
    """

    latitude: float
    longitude: float
    height: float = 0.0

    def __post_init__(self) -> None:
        v = check_geodetic((self.latitude, self.longitude, self.height), "the geodetic origin")
        for name, x in zip(("latitude", "longitude", "height"), v, strict=True):
            object.__setattr__(self, name, x)

    def to_list(self) -> list[float]:
        """``[latitude, longitude, height]``, as the geometry file gives it."""
        return [self.latitude, self.longitude, self.height]

    def to_local(self, latitude: ArrayLike, longitude: ArrayLike, height: ArrayLike = 0.0
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """East, north and up (m) of geodetic points (degrees, degrees, m) in this origin's frame."""
        e, n, u = pymap3d.geodetic2enu(np.asarray(latitude, float), np.asarray(longitude, float),
                                       np.asarray(height, float), self.latitude, self.longitude, self.height)
        return np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)

    def to_geodetic(self, east: ArrayLike, north: ArrayLike, up: ArrayLike = 0.0
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Latitude, longitude (degrees) and height (m) of local points (east, north, up in m); the inverse of
        :meth:`to_local`.  A 2-D position has ``up = 0``: a point on the tangent plane through the origin."""
        lat, lon, h = pymap3d.enu2geodetic(np.asarray(east, float), np.asarray(north, float), np.asarray(up, float),
                                           self.latitude, self.longitude, self.height)
        return np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)

    def columns(self, states: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """Each state's position as ``latitude`` and ``longitude`` (degrees) and, for 3-D states, ``height``
        (m): the track file's and JSON's geodetic columns.  2-D states lie on the tangent plane through the
        origin (``up = 0``)."""
        x = np.atleast_2d(np.asarray(states, dtype=float))
        d = x.shape[1] // 2
        lat, lon, h = self.to_geodetic(x[:, 0], x[:, 1], x[:, 2] if d == 3 else 0.0)
        out = {"latitude": np.atleast_1d(lat), "longitude": np.atleast_1d(lon)}
        if d == 3:
            out["height"] = np.atleast_1d(h)
        return out
