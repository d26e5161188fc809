r"""Plane-sphere culling that never loses a hit: the radius inflation ``r'`` and its domain.

The tester keeps a sphere when NOT(``|d| > r'``), ``d`` the computed ``n.C + p``
(:mod:`raplas_hdl.model.plane_sphere`). This module chooses ``r'`` so that every ray of a
bundle that meets a sphere keeps it in *both* of its planes, although the planes, the
rays, the spheres and the arithmetic are all quantised. The derivation is repeated in
``docs/plane-culling.md``.

Notation
--------
Hats are encoded values (exact dyadic numbers): the ray ``(O, D)``, the plane ``(n, p)``,
the sphere ``(C, r)`` with ``r = encode(r_float, direction="up")``. ``u = 2**-man_bits``;
``phi = 2**emin`` (the flush-to-zero threshold); ``g3 = (1+u)**3 - 1``.

"The ray meets the sphere" means: some point ``X = O + t D`` (any real ``t``: the bound
holds for the whole line, so for the ray too) has ``|X - C| <= r``, exactly.

1. Geometry. With ``f(x) = n.x + p`` (exact):
   ``f(C) = (n.O + p) + t (n.D) + n.(C - X)``, and ``|t| |D| = |X - O| <= |C| + |O| + r``,
   so ``|f(C)| <= eps_O + delta (|C| + |O| + r) + nu r`` where
   ``eps_O = |n.O + p|`` (how far the encoded plane misses the encoded origin),
   ``delta = |n.D| / |D|`` (the sine of the angle between the encoded ray and the
   encoded plane) and ``nu = |n|``.
2. Arithmetic. Every operation of the contract, in every rounding (``chop`` included),
   returns ``x + e`` with ``|e| <= u T + phi`` where ``T = |a| + |b|`` for a sum and
   ``|a b|`` for a product (``rtz``/``rne``: correct rounding; ``chop``: less than one ulp
   of the larger operand; ``phi``: a flush to zero), and never a magnitude above
   ``(1+u) T``. Following the tester's order (three products; ``mx+my`` and ``mz+p``;
   their sum) gives
   ``|d - f(C)| <= g3 (sum_i |n_i C_i| + |p|) + 6 phi <= g3 (nu |C| + |p|) + 6 phi``.
   So the sphere is kept whenever
   ``r' >= nu r + eps_O + delta (|C| + |O| + r) + g3 (nu |C| + |p|) + 6 phi``.       (*)
3. The budget of a bundle. :class:`~raplas_hdl.model.bundles.RayBundle` encodes normals
   toward zero (``nu <= 1``), directions with the format's rounding
   (``|D_enc - D| <= u``), and ``p = -(n_enc . O_enc)`` in float64 before encoding it
   (``|p| <= (1+u) |O|``, ``eps_O <= (u + 2**-50) |O| + phi``). Hence
   ``delta <= delta0 = (2u + u^2) / (1-u) * (1 + 2**-20) + 4 phi`` (``2**-20`` absorbs
   float64 errors in building the bundle) and ``nu <= nu0 = 1 + 2**-40``. With a bound
   ``|O| <= o_max`` everything that depends on the bundle is covered by the constant
   ``B0 = ((u + 2**-50) + delta0 + g3 (1+u)) o_max nu0 + phi``.

Where each part lives
---------------------
*Sphere Memory* (written once per scene, independent of the bundle)::

    r' = up( (nu0 + delta0) r + (delta0 + g3 nu0) |C| + B0 + 6 phi + margin )

``up`` is ``encode(..., direction="up")`` of a float64 value computed with a relative
allowance of ``2**-46`` for its own float64 rounding; ``margin`` is the caller's extra
absolute slack (the ray-triangle test's own tolerance).

*Per bundle* (travels with the planes): the bundle's own ``nu``, ``delta`` and
``B = max over planes of eps_O + delta |O| + g3 |p|``, measured on its encoded planes and
rays by :func:`bundle_slack` in ``O(rows*cols)``; the host checks them against the
budget (:meth:`CullingBudget.admits`) instead of rewriting Sphere Memory. A bundle over
budget (``|O| > o_max``, or a near-degenerate bundle whose float64 construction lost
more than the ``2**-20`` allowance) is unguaranteed: the host must not cull with it.

Domain
------
The bound (*) holds when no operation overflows. With ``L = 2**(emax-3)``:
``|O| <= o_max <= L``, ``|C| <= L`` and ``0 <= r <= L`` give ``|d| < 2**(emax-1)`` and a
finite ``r'``. There is no lower bound: flushes are in ``6 phi``. Spheres outside the
domain (or non-finite) get ``r' = +inf`` and are counted as unguaranteed: the tester
keeps them on every plane, so they are never culled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from raplas_hdl.fp import FPFormat, check_format
from raplas_hdl.fp import model as fpm

__all__ = ["CullingBudget", "BundleSlack", "bundle_slack", "bundle_slacks", "slack_arrays",
           "encode_spheres"]

#: Relative allowance for float64 rounding when r' is computed before encoding it up.
_F64_ALLOWANCE = 2.0 ** -46
#: Relative allowance for float64 errors in building a bundle's planes and rays.
_BUILD_ALLOWANCE = 2.0 ** -20
#: ``nu0 = 1 + 2**-40``: the budget's bound on ``|n|`` (normals are encoded toward zero
#: from float64 unit vectors, so ``|n| <= 1 + 2**-51``).
_NU_ALLOWANCE = 2.0 ** -40


@dataclass(frozen=True)
class BundleSlack:
    """What one bundle's quantisation costs (all upper bounds, scene units).

    Attributes
    ----------
    nu : float
        Largest ``|n|`` of its encoded normals.
    delta : float
        Largest ``|n.D| / |D|`` over every ray and its two planes.
    b : float
        Largest ``eps_O + delta |O| + g3 |p|`` over its planes.
    o_norm : float
        ``|O|`` of the encoded origin.
    """

    nu: float
    delta: float
    b: float
    o_norm: float


class CullingBudget:
    """The closed-form radius inflation of a format and a domain.

    Parameters
    ----------
    fmt : FPFormat
    o_max : float
        Bound on ``|O|`` of every bundle (scene units); at most ``2**(emax-3)``.
    margin : float
        Extra absolute slack added to every radius (default 0).

    Attributes
    ----------
    u, phi, g3, nu0, delta0, b0 : float
        The constants of the derivation (module docstring).
    limit : float
        ``L = 2**(emax-3)``: the domain bound on ``|C|`` and ``r``.
    coef_r, coef_c, const : float
        ``r' = up(coef_r * r + coef_c * |C| + const)`` before the float64 allowance.

    Raises
    ------
    ValueError
        When ``o_max`` or ``margin`` is negative, not finite, or ``o_max`` exceeds ``L``.
    """

    def __init__(self, fmt: FPFormat, o_max: float, margin: float = 0.0):
        check_format(fmt)
        self.fmt = fmt
        self.limit = 2.0 ** (fmt.emax - 3)
        if not (math.isfinite(o_max) and 0 <= o_max <= self.limit):
            raise ValueError(f"o_max must be between 0 and 2**(emax-3) = {self.limit:g} "
                             f"for {fmt}, not {o_max!r}")
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be a finite non-negative number, not {margin!r}")
        self.o_max = float(o_max)
        self.margin = float(margin)
        u = self.u = fmt.ulp
        phi = self.phi = fmt.min_value
        self.g3 = (1 + u) ** 3 - 1
        self.delta0 = (2 * u + u * u) / (1 - u) * (1 + _BUILD_ALLOWANCE) + 4 * phi
        self.eps0 = (u + 2.0 ** -50) * self.o_max + phi
        self.nu0 = 1 + _NU_ALLOWANCE
        self.b0 = ((u + 2.0 ** -50 + self.delta0 + self.g3 * (1 + u)) * self.o_max
                   * (1 + _NU_ALLOWANCE) + phi)
        self.coef_r = self.nu0 + self.delta0
        self.coef_c = self.delta0 + self.g3 * self.nu0
        self.const = self.b0 + 6 * phi + self.margin

    def in_domain(self, centres, radii) -> np.ndarray:
        """Spheres (bit patterns) for which the bound holds: finite, ``|C| <= L``,
        ``0 <= r <= L``."""
        c = fpm.decode(np.asarray(centres, np.uint32), self.fmt)
        r = fpm.decode(np.asarray(radii, np.uint32), self.fmt)
        with np.errstate(invalid="ignore", over="ignore"):
            cn = np.sqrt(np.sum(c * c, axis=-1))
            return (np.isfinite(cn) & np.isfinite(r) & (cn <= self.limit) & (r >= 0)
                    & (r <= self.limit))

    def inflate(self, centres, radii):
        """Inflated radii ``r'`` of encoded spheres.

        Parameters
        ----------
        centres : array of uint32, shape (S, 3)
        radii : array of uint32, shape (S,)
            Encoded radii (encode them with ``direction="up"``).

        Returns
        -------
        r_inflated : ndarray of uint32, shape (S,)
            ``r'``; ``+inf`` for spheres outside the domain (never culled).
        in_domain : ndarray of bool, shape (S,)
        """
        ok = self.in_domain(centres, radii)
        c = fpm.decode(np.asarray(centres, np.uint32), self.fmt)
        r = fpm.decode(np.asarray(radii, np.uint32), self.fmt)
        with np.errstate(invalid="ignore", over="ignore"):
            cn = np.sqrt(np.sum(c * c, axis=-1))
            value = (self.coef_r * r + self.coef_c * cn + self.const) * (1 + _F64_ALLOWANCE)
        value = np.where(ok, value, np.inf)
        return fpm.encode(value, self.fmt, direction="up"), ok

    def admits(self, slack: BundleSlack) -> bool:
        """True when a bundle's own slack fits the budget that ``r'`` was built with."""
        return (slack.nu <= self.nu0 and slack.delta <= self.delta0 and slack.b <= self.b0
                and slack.o_norm <= self.o_max)

    def admits_arrays(self, slack: dict) -> np.ndarray:
        """:meth:`admits` of every bundle of :func:`slack_arrays`' result (bool array)."""
        return ((slack["nu"] <= self.nu0) & (slack["delta"] <= self.delta0)
                & (slack["b"] <= self.b0) & (slack["o_norm"] <= self.o_max))

    def __repr__(self):
        return (f"CullingBudget({self.fmt}, o_max={self.o_max:g}, margin={self.margin:g}: "
                f"r' = up({self.coef_r!r} r + {self.coef_c:.6g} |C| + {self.const:.6g}))")


def encode_spheres(centres, radii, budget: CullingBudget):
    """Encode float64 spheres for Sphere Memory.

    Returns
    -------
    c : ndarray of uint32, shape (S, 3)
        Centres with the format's rounding.
    r : ndarray of uint32, shape (S,)
        Radii rounded up (the encoded sphere contains the float64 one about its centre).
    r_inflated : ndarray of uint32, shape (S,)
        ``r'``.
    in_domain : ndarray of bool, shape (S,)

    Raises
    ------
    ValueError
        When the shapes do not match.
    """
    centres = np.asarray(centres, np.float64)
    radii = np.asarray(radii, np.float64)
    if centres.ndim != 2 or centres.shape[1] != 3 or radii.shape != centres.shape[:1]:
        raise ValueError(f"centres must be (S, 3) and radii (S,), not {centres.shape} and "
                         f"{radii.shape}")
    c = fpm.encode(centres, budget.fmt)
    r = fpm.encode(radii, budget.fmt, direction="up")
    r_inf, ok = budget.inflate(c, r)
    return c, r, r_inf, ok


def bundle_slack(plane_n, plane_p, origin, directions, rows: int, cols: int,
                 fmt: FPFormat) -> BundleSlack:
    """Measure a bundle's quantisation slack from its *encoded* planes and rays.

    Parameters
    ----------
    plane_n : array of uint32, shape (rows+cols, 3)
    plane_p : array of uint32, shape (rows+cols,)
    origin : array of uint32, shape (3,)
    directions : array of uint32, shape (rows*cols, 3)
    rows, cols : int
    fmt : FPFormat

    Returns
    -------
    BundleSlack
        Upper bounds (float64 products of encoded values are exact for ``man_bits <= 25``;
        each sum is widened by its float64 error bound).
    """
    return bundle_slacks([(plane_n, plane_p, origin, directions, rows, cols)], fmt)[0]


def bundle_slacks(encoded, fmt: FPFormat) -> list[BundleSlack]:
    """:func:`bundle_slack` of many bundles: ``encoded`` holds tuples
    ``(plane_n, plane_p, origin, directions, rows, cols)``."""
    if fmt.man_bits > 25:
        raise ValueError("bundle_slack needs exact float64 products: man_bits <= 25")
    encoded = list(encoded)
    parts = []
    for k in range(4):
        arrays = [np.asarray(e[k], np.uint32).reshape(-1) for e in encoded]
        flat = fpm.decode(np.concatenate(arrays), fmt)
        parts.append(np.split(flat, np.cumsum([a.size for a in arrays])[:-1]))
    return [_slack(n.reshape(-1, 3), p, o, d.reshape(-1, 3), e[4], e[5], fmt)
            for n, p, o, d, e in zip(*parts, encoded)]


def _slack(n, p, o, d, rows, cols, fmt) -> BundleSlack:
    sl = slack_arrays(n[None], p[None], o[None], d[None], rows, cols, fmt, decoded=True)
    return BundleSlack(nu=float(sl["nu"][0]), delta=float(sl["delta"][0]), b=float(sl["b"][0]),
                       o_norm=float(sl["o_norm"][0]))


def slack_arrays(n, p, o, d, rows: int, cols: int, fmt: FPFormat, decoded: bool = False):
    """:func:`bundle_slack` of ``B`` bundles of one size given as arrays.

    Parameters
    ----------
    n : array, shape (B, rows+cols, 3)
    p : array, shape (B, rows+cols)
    o : array, shape (B, 3)
    d : array, shape (B, rows*cols, 3)
        Encoded planes and rays (bit patterns), or their decoded values with ``decoded``.
    rows, cols : int
    fmt : FPFormat

    Returns
    -------
    dict
        ``nu``, ``delta``, ``b``, ``o_norm``: float64 arrays (B,) (see :class:`BundleSlack`).
    """
    if fmt.man_bits > 25:
        raise ValueError("bundle_slack needs exact float64 products: man_bits <= 25")
    if not decoded:
        n, p, o, d = (fpm.decode(np.asarray(x, np.uint32), fmt) for x in (n, p, o, d))
    tiny = 2.0 ** -50
    nu = np.max(np.sqrt(np.sum(n * n, axis=2)) * (1 + tiny), axis=1)
    ids = np.arange(rows * cols)
    dn = np.sqrt(np.sum(d * d, axis=2)) * (1 - tiny)
    delta = np.zeros(len(n))
    for planes in (ids // cols, rows + ids % cols):
        terms = n[:, planes] * d
        dot = np.abs(terms.sum(axis=2)) + 4 * tiny * np.abs(terms).sum(axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.maximum(delta, np.max(dot / dn, axis=1))
    terms = np.concatenate([n * o[:, None, :], p[:, :, None]], axis=2)
    eps = np.abs(terms.sum(axis=2)) + 4 * tiny * np.abs(terms).sum(axis=2)
    o_norm = np.sqrt(np.sum(o * o, axis=1)) * (1 + tiny)
    g3 = (1 + fmt.ulp) ** 3 - 1
    b = np.max(eps + delta[:, None] * o_norm[:, None] + g3 * np.abs(p), axis=1) * (1 + tiny)
    return {"nu": nu, "delta": delta, "b": b, "o_norm": o_norm}
