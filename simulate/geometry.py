"""Geometry of the discretised inextensible rod (paper section "Energy functional").

The rod of length 1 (lengths in units of L) is cut into ``N`` segments of length ``ds = 1/N``.
It is parametrised by the tangent angles ``theta`` (N,) and the start point ``start`` (2,), so
that every segment has exactly the length ``ds`` whatever the parameters (inextensibility).
Positions are the ``N + 1`` nodes ``xy`` (N+1, 2).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _positions(theta, x0, y0):
    n = theta.shape[0]
    ds = 1.0 / n
    xy = np.empty((n + 1, 2))
    xy[0, 0] = x0
    xy[0, 1] = y0
    for i in range(n):
        xy[i + 1, 0] = xy[i, 0] + ds * np.cos(theta[i])
        xy[i + 1, 1] = xy[i, 1] + ds * np.sin(theta[i])
    return xy


def positions(theta, start=(0.0, 0.0)) -> np.ndarray:
    """Node positions of the rod from its tangent angles.

    Parameters
    ----------
    theta : (N,) array
        Tangent angle of every segment (radians).
    start : (2,) array-like
        Position of node 0.

    Returns
    -------
    (N+1, 2) float64 array
        ``xy[i+1] = xy[i] + (cos theta_i, sin theta_i) / N``.

    Raises
    ------
    ParameterError
        ``theta`` is not a 1-d array of N >= 1 angles.
    """
    theta = checked_angles(theta)
    return _positions(theta, float(start[0]), float(start[1]))


def checked_angles(theta) -> np.ndarray:
    """``theta`` as a contiguous float64 array of N >= 1 tangent angles.

    Values are not checked: the minimisers evaluate the energy on every step, and a step
    gone non-finite is theirs to stop on (a NaN energy), not an error.

    Parameters
    ----------
    theta : array-like

    Returns
    -------
    (N,) float64 array
        ``theta`` itself when it is one already.

    Raises
    ------
    ParameterError
        Naming its shape (an empty ``theta`` divided by zero).
    """
    arr = np.ascontiguousarray(theta, dtype=np.float64)
    if arr.ndim == 1 and arr.size:
        return arr
    from crosssection.core.errors import ParameterError

    raise ParameterError(f"theta must be a 1-d array of N >= 1 tangent angles, got shape "
                         f"{arr.shape}")


def angles(xy) -> tuple[np.ndarray, np.ndarray]:
    """Tangent angles and start point of a polyline (inverse of :func:`positions`).

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, finite, N >= 1.

    Returns
    -------
    theta : (N,) array
        Unwrapped tangent angles (consecutive differences in (-pi, pi]).
    start : (2,) array
        ``xy[0]``.

    Raises
    ------
    ParameterError
        ``xy`` is not such an array (see :func:`checked_rod`).
    """
    xy = checked_rod(xy)
    d = np.diff(xy, axis=0)
    theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return theta, xy[0].copy()


def sharp_nodes(xy, turn_deg: float) -> int:
    """Nodes of a polyline whose tangent turns by more than ``turn_deg`` degrees.

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, finite, N >= 1.
    turn_deg : float
        Turn angle in degrees, in [0, 180).

    Returns
    -------
    int

    Raises
    ------
    ParameterError
        ``xy`` is not such an array (see :func:`checked_rod`).
    """
    theta, _ = angles(xy)
    return int(np.count_nonzero(np.abs(np.diff(theta)) > math.radians(turn_deg)))


def trapezoid_weights(n_segments: int) -> np.ndarray:
    """Trapezoid weights of the N+1 nodes for integrals ``int f ds`` over the rod.

    Parameters
    ----------
    n_segments : int
        Number of segments N, a whole number >= 1.

    Returns
    -------
    (N+1,) array
        ``ds`` at interior nodes, ``ds/2`` at both ends; sums to 1.

    Raises
    ------
    ParameterError
        ``n_segments`` is not a whole number >= 1.
    """
    from simulate.checks import check_whole

    return _trapezoid_weights(check_whole("n_segments", n_segments, low=1))


def _trapezoid_weights(n_segments):
    """:func:`trapezoid_weights` without the check."""
    w = np.full(n_segments + 1, 1.0 / n_segments)
    w[0] *= 0.5
    w[-1] *= 0.5
    return w


def center_of_mass(xy) -> np.ndarray:
    """Centre of mass of the rod (trapezoid rule along the arclength), shape (2,).

    This is the translation that minimises the confinement energy ``Lambda int R^2 ds``.

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, finite, N >= 1.

    Returns
    -------
    (2,) float64 array

    Raises
    ------
    ParameterError
        ``xy`` is not such an array (see :func:`checked_rod`).
    """
    xy = checked_rod(xy)
    w = _trapezoid_weights(xy.shape[0] - 1)
    return w @ xy


def radius_of_gyration(xy) -> float:
    """``Rg = sqrt(int R^2 ds)`` about the origin (paper Eq. (11), L = 1).

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, finite, N >= 1.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        ``xy`` is not such an array (see :func:`checked_rod`).
    """
    xy = checked_rod(xy)
    w = _trapezoid_weights(xy.shape[0] - 1)
    return float(np.sqrt(w @ np.einsum("ij,ij->i", xy, xy)))


__all__ = ["positions", "angles", "trapezoid_weights", "center_of_mass", "radius_of_gyration",
           "checked_rod", "checked_angles", "is_point"]


def checked_rod(xy, *, min_segments: int = 1) -> np.ndarray:
    """``xy`` as an (N+1, 2) float array of finite numbers with ``N >= min_segments``.

    The check of the public functions taking a rod, once per call: a float64 array of the
    right shape costs one dot product (the minimisers call some of these functions in their loops).

    Parameters
    ----------
    xy : array-like
        What the caller passed as the rod's node positions.
    min_segments : int
        Fewest segments N accepted.

    Returns
    -------
    (N+1, 2) float64 array
        ``xy`` itself when it is one already.

    Raises
    ------
    ParameterError
        Naming ``xy``, its shape (with a hint when it looks transposed) and the cause.
    """
    if (type(xy) is np.ndarray and xy.dtype == np.float64 and xy.ndim == 2
            and xy.shape[1] == 2 and xy.shape[0] > min_segments
            and math.isfinite(np.dot(xy.ravel(), xy.ravel()))):
        # the usual rod, accepted for the cost of one dot product (finite only if every
        # coordinate is); the path below explains what is wrong, or accepts coordinates so
        # large that their squares overflow
        return xy
    import reprlib

    from crosssection.core.errors import ParameterError

    need = f"xy must be an (N+1, 2) array of finite numbers with N >= {min_segments}"
    try:
        arr = np.asarray(xy, float)
    except (TypeError, ValueError):
        raise ParameterError(f"{need}, got {reprlib.repr(xy)}") from None
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < min_segments + 1:
        hint = (" (transposed? pass xy.T)"
                if arr.ndim == 2 and arr.shape[0] == 2 and arr.shape[1] != 2 else "")
        raise ParameterError(f"{need}, got shape {arr.shape}{hint}")
    bad = int(np.count_nonzero(~np.isfinite(arr)))
    if bad:
        raise ParameterError(f"{need}, got {bad} non-finite coordinate(s)")
    return arr


def is_point(p) -> bool:
    """Whether ``p`` is two finite numbers."""
    try:
        arr = np.asarray(p, float)
    except (TypeError, ValueError):
        return False
    return arr.shape == (2,) and bool(np.isfinite(arr).all())
