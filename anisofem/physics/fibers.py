"""Fiber fields wound about an axis (helices), the fields a wound actuator's fibers make.

At a point c, with s = (c - o) . a its position along the axis a (unit) through o and e_t the
circumferential direction a x (the radial direction), a winding angle alpha from the axis
gives d = cos(alpha) a + sin(alpha) e_t (90 degrees: hoops). A crossed winding puts +alpha and
-alpha on alternate tets.
"""
import numpy as np


def helix_frame(centers, axis, origin):
    """(s (m,) m along the axis, e_t (m, 3) circumferential unit vectors) at points (m, 3), for
    a unit axis (3,) through origin (3,); ValueError where a point lies on the axis (within
    tolerance, m)."""
    c = np.asarray(centers, dtype=float) - origin
    s = c @ axis
    radial = c - s[:, None] * axis
    r = np.linalg.norm(radial, axis=1)
    if (r <= 1e-12 * max(1.0, float(np.abs(c).max()))).any():
        raise ValueError("a tet's center lies on the axis, where a helix has no direction")
    return s, np.cross(axis, radial / r[:, None])


def helix_directions(axis, around, angles, crossed=False):
    """Unit fiber directions (m, 3) at winding angles (m,) radians, with e_t `around` (m, 3);
    crossed: alternate tets wound at -angle."""
    angles = np.array(angles, dtype=float)
    if crossed:
        angles[1::2] *= -1.0
    return np.cos(angles)[:, None] * axis + np.sin(angles)[:, None] * around


def helix_slopes(axis, around, angles, crossed=False):
    """d(direction)/d(angle) (m, 3) of helix_directions, per radian."""
    sign = np.ones(len(angles))
    if crossed:
        sign[1::2] = -1.0
    a = sign * np.asarray(angles, dtype=float)
    return sign[:, None] * (-np.sin(a)[:, None] * axis + np.cos(a)[:, None] * around)


def segments(s, count):
    """(m,) the index of the equal slab (of count over s's range) each position s (m,) is in."""
    span = np.ptp(s)
    share = (s - s.min()) / span if span > 0 else np.zeros_like(s)
    return np.minimum((share * count).astype(int), count - 1)
