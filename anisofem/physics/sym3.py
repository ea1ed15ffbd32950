"""Closed-form 3x3 linear algebra for the element kernels (numba, inlined): the symmetric
eigen-decomposition, positive part and definiteness test, and the cofactor matrix."""
import math

from numba import njit


@njit(cache=True, inline="always")
def eigen(a, w, V):
    """Eigenvalues w (3,) and orthonormal eigenvectors (columns of V, 3x3) of the symmetric
    3x3 matrix a (read only). Closed form, after Eberly's robust scheme: of B = (a - tr(a)/3 I)
    / p, the root of the characteristic cubic farthest from the other two (trigonometric
    solution; it is accurate where the other two nearly coincide), its eigenvector as the
    longest cross product of two rows of B - beta I, the other two from the 2x2 restriction
    of B to the orthogonal plane, diagonalized by one Jacobi rotation; the eigenvalues are the
    Rayleigh quotients. No iteration, accurate for nearly repeated eigenvalues too."""
    m = max(abs(a[0, 0]), abs(a[0, 1]), abs(a[0, 2]), abs(a[1, 1]), abs(a[1, 2]),
            abs(a[2, 2]))
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    if m == 0.0:
        w[0] = w[1] = w[2] = 0.0
        return
    q = (a[0, 0] + a[1, 1] + a[2, 2]) / (3.0 * m)
    b00, b11, b22 = a[0, 0] / m - q, a[1, 1] / m - q, a[2, 2] / m - q
    b01, b02, b12 = a[0, 1] / m, a[0, 2] / m, a[1, 2] / m
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22
                   + 2.0 * (b01 * b01 + b02 * b02 + b12 * b12)) / 6.0)
    if p == 0.0:
        w[0] = w[1] = w[2] = q * m
        return
    b00, b11, b22, b01, b02, b12 = b00 / p, b11 / p, b22 / p, b01 / p, b02 / p, b12 / p
    half_det = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
                      + b02 * (b01 * b12 - b11 * b02))
    phi = math.acos(min(1.0, max(-1.0, half_det))) / 3.0
    # the root farthest from the other two: the largest when half_det >= 0, else the smallest
    beta = 2.0 * math.cos(phi if half_det >= 0.0 else phi + 2.0 * math.pi / 3.0)
    e0, e1, e2 = V[:, 0], V[:, 1], V[:, 2]
    if not _null_vector(b00 - beta, b01, b02, b11 - beta, b12, b22 - beta, e0):
        e0[0], e0[1], e0[2] = 1.0, 0.0, 0.0
    # u, v: an orthonormal basis of the plane orthogonal to e0
    if abs(e0[0]) > abs(e0[1]):
        inv = 1.0 / math.sqrt(e0[0] * e0[0] + e0[2] * e0[2])
        u0, u1, u2 = -e0[2] * inv, 0.0, e0[0] * inv
    else:
        inv = 1.0 / math.sqrt(e0[1] * e0[1] + e0[2] * e0[2])
        u0, u1, u2 = 0.0, e0[2] * inv, -e0[1] * inv
    v0, v1, v2 = e0[1] * u2 - e0[2] * u1, e0[2] * u0 - e0[0] * u2, e0[0] * u1 - e0[1] * u0
    # the 2x2 restriction [u v]^T B [u v], diagonalized by one Jacobi rotation
    bu0 = b00 * u0 + b01 * u1 + b02 * u2
    bu1 = b01 * u0 + b11 * u1 + b12 * u2
    bu2 = b02 * u0 + b12 * u1 + b22 * u2
    bv0 = b00 * v0 + b01 * v1 + b02 * v2
    bv1 = b01 * v0 + b11 * v1 + b12 * v2
    bv2 = b02 * v0 + b12 * v1 + b22 * v2
    m00 = u0 * bu0 + u1 * bu1 + u2 * bu2
    m01 = u0 * bv0 + u1 * bv1 + u2 * bv2
    m11 = v0 * bv0 + v1 * bv1 + v2 * bv2
    c, s = 1.0, 0.0
    if m01 != 0.0:
        theta = (m11 - m00) / (2.0 * m01)
        t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
        c = 1.0 / math.sqrt(t * t + 1.0)
        s = t * c
    e1[0], e1[1], e1[2] = c * u0 - s * v0, c * u1 - s * v1, c * u2 - s * v2
    e2[0], e2[1], e2[2] = s * u0 + c * v0, s * u1 + c * v1, s * u2 + c * v2
    # Rayleigh quotients: accurate where the trigonometric roots are not (nearly double ones)
    for k in range(3):
        e = V[:, k]
        w[k] = m * (q + p * (b00 * e[0] * e[0] + b11 * e[1] * e[1] + b22 * e[2] * e[2]
                             + 2.0 * (b01 * e[0] * e[1] + b02 * e[0] * e[2] + b12 * e[1] * e[2])))


@njit(cache=True, inline="always")
def _null_vector(a00, a01, a02, a11, a12, a22, out):
    """Write into out a unit vector orthogonal to the rows of the symmetric 3x3 matrix given
    by its upper triangle (rank 2): their longest cross product. False where all vanish."""
    x0, y0, z0 = a01 * a12 - a02 * a11, a02 * a01 - a00 * a12, a00 * a11 - a01 * a01
    x1, y1, z1 = a01 * a22 - a02 * a12, a02 * a02 - a00 * a22, a00 * a12 - a01 * a02
    x2, y2, z2 = a11 * a22 - a12 * a12, a12 * a02 - a01 * a22, a01 * a12 - a11 * a02
    n0 = x0 * x0 + y0 * y0 + z0 * z0
    n1 = x1 * x1 + y1 * y1 + z1 * z1
    n2 = x2 * x2 + y2 * y2 + z2 * z2
    if n0 >= n1 and n0 >= n2:
        x, y, z, n = x0, y0, z0, n0
    elif n1 >= n2:
        x, y, z, n = x1, y1, z1, n1
    else:
        x, y, z, n = x2, y2, z2, n2
    if n == 0.0:
        return False
    inv = 1.0 / math.sqrt(n)
    out[0], out[1], out[2] = x * inv, y * inv, z * inv
    return True


@njit(cache=True, inline="always")
def positive_part(S, out, w, V):
    """Write the positive part of the symmetric 3x3 matrix S into out (w (3,), V (3, 3):
    scratch)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = S[i, j]
    eigen(out, w, V)
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    for k in range(3):
        if w[k] > 0.0:
            for i in range(3):
                for j in range(3):
                    out[i, j] += w[k] * V[i, k] * V[j, k]


@njit(cache=True, inline="always")
def has_negative_eigenvalue(S):
    """True when the symmetric 3x3 matrix S is not positive semi-definite (Sylvester test)."""
    if S[0, 0] < 0.0 or S[1, 1] < 0.0 or S[2, 2] < 0.0:
        return True
    if S[0, 0] * S[1, 1] - S[0, 1] ** 2 < 0.0:
        return True
    if S[0, 0] * S[2, 2] - S[0, 2] ** 2 < 0.0:
        return True
    if S[1, 1] * S[2, 2] - S[1, 2] ** 2 < 0.0:
        return True
    det = (S[0, 0] * (S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1])
           - S[0, 1] * (S[1, 0] * S[2, 2] - S[1, 2] * S[2, 0])
           + S[0, 2] * (S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]))
    return det < 0.0


@njit(cache=True, inline="always")
def cofactor(F, cof):
    """cof = the cofactor matrix of the 3x3 F (det F = F[0] . cof[0])."""
    cof[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    cof[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    cof[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    cof[1, 0] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    cof[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    cof[1, 2] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    cof[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    cof[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    cof[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
