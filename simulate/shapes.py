"""Hand-built rods of known contact structure (hairpin, accordion, spiral, double loop), in
units of L.

Used to check the contact analysis and the renderer against shapes whose stacks, junctions and
voids are known by construction.
"""
from __future__ import annotations

import numpy as np

__all__ = ["resample", "lines", "hairpin", "accordion", "spiral", "double_loop", "transform"]


def resample(curve, n=300):
    """Dense curve -> rod of length 1 in n (nearly) equal segments, centred at the origin."""
    curve = np.asarray(curve, float)
    s = np.r_[0, np.cumsum(np.hypot(*np.diff(curve, axis=0).T))]
    t = np.linspace(0, s[-1], n + 1)
    xy = np.c_[np.interp(t, s, curve[:, 0]), np.interp(t, s, curve[:, 1])]
    xy /= np.hypot(*np.diff(xy, axis=0).T).sum()
    return xy - xy.mean(axis=0)


def lines(*pts, m=2000):
    t = np.linspace(0, 1, m)[:, None]
    return np.concatenate([np.asarray(a) * (1 - t) + np.asarray(b) * t
                           for a, b in zip(pts[:-1], pts[1:])])


def hairpin(g, arm=0.3):
    """Folded rod: arms in contact (gap g) over ``arm``, fold cap at one end, arms diverging
    into free ends at the other (one Y junction)."""
    th = np.linspace(np.pi / 2, -np.pi / 2, 400)
    cap = np.c_[arm + g / 2 * np.cos(th), g / 2 * np.sin(th)]
    return np.concatenate([lines((-0.1, 0.06), (0, g / 2), (arm, g / 2)), cap,
                           lines((arm, -g / 2), (0, -g / 2), (-0.1, -0.06))])


def accordion(layers, g, length=1.0):
    """Rod folded flat ``layers`` times: straight layers ``g`` apart joined by half-circle caps
    of diameter ``g``, the rod's ends free at both sides (one stack of ``layers`` branches, no
    junction)."""
    cap = np.pi * g / 2
    arm = (length - (layers - 1) * cap) / layers
    th = np.linspace(-np.pi / 2, np.pi / 2, 400)
    parts = []
    for i in range(layers):
        y = i * g
        ends = ((0.0, y), (arm, y)) if i % 2 == 0 else ((arm, y), (0.0, y))
        parts.append(lines(*ends))
        if i < layers - 1:  # the cap turns round the end the layer ran to
            x0, sign = ends[1][0], (1 if i % 2 == 0 else -1)
            parts.append(np.c_[x0 + sign * g / 2 * np.cos(th), y + g / 2 + g / 2 * np.sin(th)])
    return np.concatenate(parts)


def spiral(turns, g):
    th = np.linspace(0, 2 * np.pi * turns, 20000)
    r = 1 / (2 * np.pi * turns) - g * turns / 2 + g * th / (2 * np.pi)
    return np.c_[r * np.cos(th), r * np.sin(th)]


def double_loop(g, r0=0.06):
    """1.5 turns wound with gap g: the second half-turn lies on the first (stack n=2), a tail
    enters from the inside and one leaves outwards (2 junctions, 1 void)."""
    th = np.linspace(0, 3 * np.pi, 20000)
    r = r0 + g * th / (2 * np.pi)
    c = np.c_[r * np.cos(th), r * np.sin(th)]
    return np.concatenate([lines((0.6 * r0, 0), (r0, 0)), c, lines(c[-1], c[-1] - (0.1, 0))])


def transform(xy, rng):
    a = rng.uniform(0, 2 * np.pi)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    xy = xy @ rot.T
    return xy[::-1].copy() if rng.random() < 0.5 else xy
