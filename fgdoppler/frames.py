r"""Cartesian frames: a geometry's own coordinates inside the user's world.

A :class:`Frame` is a rigid transform between *world* coordinates (the
user's) and *local* coordinates (a frame attached to the sensors):

.. math::

    \mathbf u = \mathbf B(\mathbf p - \mathbf o), \qquad
    \mathbf p = \mathbf o + \mathbf B'\mathbf u,

with origin :math:`\mathbf o` and an orthogonal basis :math:`\mathbf B` whose
rows are the local axes in world coordinates (:math:`\det\mathbf B = \pm 1`: a
reflection is allowed).  A state :math:`[\mathbf p, \mathbf v]` maps as
:math:`[\mathbf B(\mathbf p - \mathbf o), \mathbf B\mathbf v]` and a covariance
as :math:`\mathbf T\mathbf P\mathbf T'` with
:math:`\mathbf T = \mathrm{diag}(\mathbf B, \mathbf B)`.

:func:`sensor_frame` is the rule that attaches a frame to a set of bistatic
pairs.  It depends only on the sensors, so a rigid motion of the whole
problem (rotation, translation, reflection) moves the frame with it and the
local coordinates of everything stay the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["AXIS_MIN_SHARE", "SENSOR_EPS", "Frame", "sensor_frame"]

FloatArray = NDArray[np.float64]

#: Where the sensors' mean offset across the reference baseline counts as zero
#: (relative to their extent): the frame is then right-handed.  Coarse enough
#: that snapping the sensors to a millimetre lattice cannot flip the side.
_SIDE_TOL = 1e-6
#: Distance (m) below which a point counts as being at a sensor (and two sensors at one place).
SENSOR_EPS = 1e-6
#: A sensor nearer the first receiver than this share of the farthest sensor's distance does not set the
#: frame's first axis: a quasi-monostatic pair (antennas metres apart in a network kilometres wide) would
#: otherwise turn the frame, and the default zone with it, with every centimetre of its survey.
AXIS_MIN_SHARE = 0.01


@dataclass(frozen=True, kw_only=True)
class Frame:
    """A rigid transform between world and local coordinates (2-D or 3-D).

    Parameters
    ----------
    origin
        World position of the local origin, length ``d``.
    basis
        ``d`` rows, the local axes as unit vectors in world coordinates
        (orthonormal; a reflection is allowed).

    Raises
    ------
    ValueError
        If the shapes differ, a value is not finite or the basis is not
        orthonormal to 1e-9.
    """

    origin: tuple[float, ...]
    basis: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        o = np.asarray(self.origin, dtype=float)
        b = np.asarray(self.basis, dtype=float)
        if o.ndim != 1 or o.size not in (2, 3) or b.shape != (o.size, o.size):
            raise ValueError(f"a frame needs a 2- or 3-vector origin and a square basis, got {o.shape}, {b.shape}")
        if not (np.all(np.isfinite(o)) and np.all(np.isfinite(b))):
            raise ValueError("frame origin and basis must be finite")
        if not np.allclose(b @ b.T, np.eye(o.size), rtol=0, atol=1e-9):
            raise ValueError("frame basis must be orthonormal")
        # + 0.0 turns -0.0 into 0.0: the identity test and every product stay exact
        object.__setattr__(self, "origin", tuple(float(v) + 0.0 for v in o))
        object.__setattr__(self, "basis", tuple(tuple(float(v) + 0.0 for v in row) for row in b))

    @classmethod
    def identity(cls, dim: int = 2) -> Frame:
        """World and local coordinates coincide."""
        return cls(origin=(0.0,) * dim, basis=tuple(tuple(float(i == j) for j in range(dim)) for i in range(dim)))

    @property
    def dim(self) -> int:
        """Spatial dimension ``d``."""
        return len(self.origin)

    @cached_property
    def o(self) -> FloatArray:
        """Origin as an array ``(d,)``."""
        return np.array(self.origin)

    @cached_property
    def B(self) -> FloatArray:
        """Basis as an array ``(d, d)`` (rows: local axes)."""
        return np.array(self.basis)

    @cached_property
    def is_identity(self) -> bool:
        """True when the transform is exactly the identity (then nothing is transformed at all)."""
        return bool(np.all(self.o == 0.0) and np.all(self.B == np.eye(self.dim)))

    @property
    def proper(self) -> bool:
        """True for a rotation, False for a rotation combined with a reflection."""
        return bool(np.linalg.det(self.B) > 0)

    # -- points and directions ------------------------------------------------------
    def points_to_local(self, p: ArrayLike) -> FloatArray:
        """World positions ``(..., d)`` in local coordinates."""
        p = np.asarray(p, dtype=float)
        return p.copy() if self.is_identity else (p - self.o) @ self.B.T

    def points_to_world(self, u: ArrayLike) -> FloatArray:
        """Local positions ``(..., d)`` in world coordinates."""
        u = np.asarray(u, dtype=float)
        return u.copy() if self.is_identity else self.o + u @ self.B

    def vectors_to_world(self, v: ArrayLike) -> FloatArray:
        """Local directions or velocities ``(..., d)`` in world coordinates (no translation)."""
        v = np.asarray(v, dtype=float)
        return v.copy() if self.is_identity else v @ self.B

    # -- states and covariances ------------------------------------------------------
    def states_to_local(self, x: ArrayLike) -> FloatArray:
        """World states ``(..., 2d)`` ``[p, v]`` in local coordinates."""
        x = np.asarray(x, dtype=float)
        if self.is_identity:
            return x.copy()
        d = self.dim
        return np.concatenate([(x[..., :d] - self.o) @ self.B.T, x[..., d:] @ self.B.T], axis=-1)

    def states_to_world(self, x: ArrayLike) -> FloatArray:
        """Local states ``(..., 2d)`` in world coordinates."""
        x = np.asarray(x, dtype=float)
        if self.is_identity:
            return x.copy()
        d = self.dim
        return np.concatenate([self.o + x[..., :d] @ self.B, x[..., d:] @ self.B], axis=-1)

    def _state_map(self, to_world: bool) -> FloatArray:
        d = self.dim
        T = np.zeros((2 * d, 2 * d))
        R = self.B.T if to_world else self.B
        T[:d, :d] = R
        T[d:, d:] = R
        return T

    def covariances_to_world(self, P: ArrayLike) -> FloatArray:
        """Local state covariances ``(..., 2d, 2d)`` in world coordinates: ``T P T'``."""
        return self._covariances(P, to_world=True)

    def covariances_to_local(self, P: ArrayLike) -> FloatArray:
        """World state covariances ``(..., 2d, 2d)`` in local coordinates."""
        return self._covariances(P, to_world=False)

    def _covariances(self, P: ArrayLike, *, to_world: bool) -> FloatArray:
        """``T P T'`` with the state map towards world or local coordinates, symmetrised."""
        P = np.asarray(P, dtype=float)
        if self.is_identity:
            return P.copy()
        T = self._state_map(to_world)
        out = T @ P @ T.T
        return 0.5 * (out + np.swapaxes(out, -1, -2))  # symmetric to the last bit, as it was

    def relative_to(self, other: Frame) -> Frame:
        r"""This frame expressed in ``other``'s local coordinates.

        With :math:`\mathbf l = \mathbf B_2(\mathbf p - \mathbf o_2)` the
        coordinates of ``other``, this frame's coordinates are
        :math:`\mathbf B_1\mathbf B_2'(\mathbf l - \mathbf B_2(\mathbf o_1 - \mathbf o_2))`.
        A frame relative to itself is exactly the identity.
        """
        if self == other:
            return Frame.identity(self.dim)
        return Frame(origin=tuple(other.B @ (self.o - other.o)), basis=tuple(map(tuple, self.B @ other.B.T)))

    def to_dict(self) -> dict[str, object]:
        """JSON/TOML-ready form."""
        return {"origin": list(self.origin), "basis": [list(r) for r in self.basis]}


def sensor_frame(tx: ArrayLike, rx: ArrayLike) -> Frame:
    r"""The frame of a set of bistatic pairs (the rule every default zone is built in).

    * origin: the receiver of the first pair;
    * first axis :math:`\mathbf e_u`: from that receiver towards its
      transmitter — or, where the first pair is monostatic or nearly so
      (its transmitter nearer than :data:`AXIS_MIN_SHARE` of the farthest
      sensor's distance), towards the first sensor that is not, in pair
      order, each pair's transmitter before its receiver;
    * second axis :math:`\mathbf e_v \perp \mathbf e_u`, on the side where the
      distinct sensors lie on average (right-handed when they average on the
      line, e.g. all sensors collinear).

    In 3-D (positions with three coordinates) the third axis is "up":

    * sensors all on the ground (every :math:`z = 0`): the 2-D frame of their
      horizontal positions and :math:`\mathbf e_w = +\mathbf z`, so that the
      zone's ``along``/``across`` mean the same as for the 2-D problem and its
      altitude band is height above the ground;
    * otherwise :math:`\mathbf e_v` is the sensors' mean offset across
      :math:`\mathbf e_u` (normalised) and
      :math:`\mathbf e_w = \pm\,\mathbf e_u \times \mathbf e_v`, the sign
      making its world :math:`z` non-negative: the normal of the sensors'
      plane on the sky's side, so that the altitude band is above them
      whichever side of the first baseline they lie on (with the right-handed
      sign it pointed into the ground when they lay on its right, and a
      target at altitude was tracked at its mirror image below the sensors).
      Any rotation about the vertical and any translation of the whole problem
      moves the frame with it, as does any rotation that keeps that normal on
      the same side of the horizontal; one that turns the sky downwards is not
      a symmetry of the problem (the band stays above the sensors).  If the sensors are
      collinear there is no such offset (the problem is symmetric about
      their line); then :math:`\mathbf e_w` is world :math:`+\mathbf z` made
      perpendicular to :math:`\mathbf e_u` and
      :math:`\mathbf e_v = \mathbf e_w \times \mathbf e_u`.

    Both 3-D rules agree for ground sensors on the left of the first baseline
    (the paper's geometries, where the frame is the identity).

    Parameters
    ----------
    tx, rx
        Transmitter and receiver positions, ``(n_pairs, d)`` with ``d`` 2 or 3.

    Raises
    ------
    ValueError
        If every sensor is at the first receiver's place (no axis).
    """
    tx = np.asarray(tx, dtype=float)
    rx = np.asarray(rx, dtype=float)
    if tx.shape[-1] == 3:
        if not np.any(tx[:, 2]) and not np.any(rx[:, 2]):
            flat = sensor_frame(tx[:, :2], rx[:, :2])
            basis3 = np.eye(3)
            basis3[:2, :2] = flat.B
            return Frame(origin=(*flat.origin, 0.0), basis=tuple(tuple(b) for b in basis3))
        return _sensor_frame_3d(tx, rx)
    o = rx[0]
    e_u = _reference_axis(tx, rx)
    e_v = np.array([-e_u[1], e_u[0]])
    basis = [e_u, e_v]
    sensors = np.unique(np.vstack([tx, rx]), axis=0)
    v = (sensors - o) @ e_v
    extent = float(np.ptp((sensors - o) @ e_u)) or 1.0
    if float(np.mean(v)) < -_SIDE_TOL * extent:
        basis[1] = -e_v
    return Frame(origin=tuple(o), basis=tuple(tuple(b) for b in basis))


def _sensor_frame_3d(tx: FloatArray, rx: FloatArray) -> Frame:
    """The 3-D rule of :func:`sensor_frame` for sensors not all on the ground."""
    o = rx[0]
    e_u = _reference_axis(tx, rx)
    sensors = np.unique(np.vstack([tx, rx]), axis=0)
    rel = sensors - o
    across = rel - np.outer(rel @ e_u, e_u)
    mean = across.mean(axis=0)
    extent = float(np.max(np.linalg.norm(rel, axis=1))) or 1.0
    if float(np.linalg.norm(mean)) > _SIDE_TOL * extent:
        e_v = mean / np.linalg.norm(mean)
        e_w = np.cross(e_u, e_v)
        if e_w[2] < 0:  # the altitude band lies on the sky's side of the sensors' plane, whatever side they lie on
            e_w = -e_w
    else:
        up = np.array([0.0, 0.0, 1.0]) if abs(e_u[2]) < 1.0 - 1e-12 else np.array([1.0, 0.0, 0.0])
        e_w = up - (up @ e_u) * e_u
        e_w /= np.linalg.norm(e_w)
        e_v = np.cross(e_w, e_u)
    return Frame(origin=tuple(o), basis=(tuple(e_u), tuple(e_v), tuple(e_w)))


def _reference_axis(tx: FloatArray, rx: FloatArray) -> FloatArray:
    r"""The unit first axis of :func:`sensor_frame`: from the first receiver to the first sensor well away.

    "Well away" is :math:`|\mathbf s_k - \mathbf r_0| \ge \max(\epsilon,\ a\,\max_j
    |\mathbf s_j - \mathbf r_0|)` with :math:`\epsilon` = :data:`SENSOR_EPS` and :math:`a` =
    :data:`AXIS_MIN_SHARE`.  That is the first pair's transmitter unless the
    pair is monostatic or nearly so; the candidates are taken in pair order,
    each pair's transmitter before its receiver, so renumbering the pairs
    after the one that supplies the axis leaves the frame alone.  Distances
    scale with the layout, so the rule commutes with a change of units.
    """
    rel = np.stack([tx, rx], axis=1).reshape(-1, tx.shape[-1]) - rx[0]
    dist = np.linalg.norm(rel, axis=1)
    far = np.flatnonzero(dist >= max(SENSOR_EPS, AXIS_MIN_SHARE * float(dist.max())))
    if far.size == 0:
        raise ValueError("every sensor is at one place: no axis for the sensors' frame")
    return np.asarray(rel[far[0]] / dist[far[0]], dtype=float)
