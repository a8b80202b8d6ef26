"""The signed distance of a point from a triangle's plane, with its exact derivatives.

The kernel of skin self-contact (:mod:`fem.self_contact`): for a slave point x_s and a
master triangle (x_a, x_b, x_c), all moving,

    g(q) = n · (x_s − x_a),    n = m / |m|,   m = (x_b − x_a) × (x_c − x_a),

with q = (x_s, x_a, x_b, x_c) ∈ R¹². Newton needs ∇g (12) and ∇²g (12 × 12) for the
penalty energy ½ κ w ⟨−g⟩²; the second derivative includes the rotation of the master's
normal, so that the tangent is the energy's true Hessian (Newton converges
quadratically while the pairs do not change). Writing D = ∂(x_s − x_a)/∂q,
E₁ = ∂(x_b − x_a)/∂q, E₂ = ∂(x_c − x_a)/∂q, [v]× the cross-product matrix and
P = (I − n nᵀ)/|m|:

    M = ∂m/∂q = −[e₂]× E₁ + [e₁]× E₂,     N = ∂n/∂q = P M,     t = P d,
    ∇g = Dᵀ n + Mᵀ t,
    ∇²g = Dᵀ N + Mᵀ T − E₁ᵀ[t]× E₂ + E₂ᵀ[t]× E₁,
    T = ∂t/∂q = (D − n ∇gᵀ − g N − t nᵀ M) / |m|.

Everything is vectorised over pairs (leading axis); ``tests/test_self_contact.py``
checks both derivatives against finite differences.
"""

from __future__ import annotations

import numpy as np

__all__ = ["barycentric", "signed_distance", "signed_distance_derivatives"]

_I = np.eye(3)
_Z = np.zeros((3, 3))
#: ∂(x_s − x_a)/∂q, ∂(x_b − x_a)/∂q, ∂(x_c − x_a)/∂q for q = (x_s, x_a, x_b, x_c).
_D = np.hstack([_I, -_I, _Z, _Z])
_E1 = np.hstack([_Z, -_I, _I, _Z])
_E2 = np.hstack([_Z, -_I, _Z, _I])


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]× for each row of ``v`` (n, 3): [v]× w = v × w, shape (n, 3, 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def signed_distance(xs: np.ndarray, xa: np.ndarray, xb: np.ndarray, xc: np.ndarray) -> np.ndarray:
    """The signed distance g of each pair (rows of (n, 3) arrays): > 0 where the normal points."""
    m = np.cross(xb - xa, xc - xa)
    return np.einsum("ij,ij->i", m, xs - xa) / np.linalg.norm(m, axis=1)


def barycentric(xs: np.ndarray, xa: np.ndarray, xb: np.ndarray, xc: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of each point's projection onto its triangle's plane."""
    e1, e2, d = xb - xa, xc - xa, xs - xa
    a11 = np.einsum("ij,ij->i", e1, e1)
    a12 = np.einsum("ij,ij->i", e1, e2)
    a22 = np.einsum("ij,ij->i", e2, e2)
    r1 = np.einsum("ij,ij->i", e1, d)
    r2 = np.einsum("ij,ij->i", e2, d)
    det = a11 * a22 - a12 * a12
    b = (a22 * r1 - a12 * r2) / det
    c = (a11 * r2 - a12 * r1) / det
    return np.column_stack([1.0 - b - c, b, c])


def signed_distance_derivatives(
    xs: np.ndarray, xa: np.ndarray, xb: np.ndarray, xc: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """g, ∇g and ∇²g with respect to q = (x_s, x_a, x_b, x_c) for each pair.

    Returns:
        ``(g, grad, hess)`` of shapes (n,), (n, 12) and (n, 12, 12); ``hess`` symmetric.
    """
    e1, e2, d = xb - xa, xc - xa, xs - xa
    m = np.cross(e1, e2)
    mu = np.linalg.norm(m, axis=1)
    n = m / mu[:, None]
    g = np.einsum("ij,ij->i", n, d)
    P = (_I - n[:, :, None] * n[:, None, :]) / mu[:, None, None]
    M = -_skew(e2) @ _E1 + _skew(e1) @ _E2  # (n, 3, 12)
    N = P @ M
    t = np.einsum("nij,nj->ni", P, d)
    grad = n @ _D + np.einsum("nij,ni->nj", M, t)
    dmu = np.einsum("ni,nij->nj", n, M)
    T = (_D[None] - n[:, :, None] * grad[:, None, :] - g[:, None, None] * N
         - t[:, :, None] * dmu[:, None, :]) / mu[:, None, None]
    St = _skew(t)
    hess = (
        np.einsum("ik,nkj->nij", _D.T, N)
        + np.einsum("nki,nkj->nij", M, T)
        - _E1.T @ St @ _E2
        + _E2.T @ St @ _E1
    )
    return g, grad, 0.5 * (hess + np.transpose(hess, (0, 2, 1)))
