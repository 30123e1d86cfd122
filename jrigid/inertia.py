"""Inertia: moments of simple shapes and a T-handle, tensors of point masses, principal axes,
checks.

Implements chapter 17.29–17.32 and Table 17.1.

An inertia is given either as principal moments ``(..., 3)`` about the body ``x, y, z``
axes, or as a symmetric tensor ``(..., 3, 3)``. The shape functions return principal
moments about the centre of mass for a uniform density; each docstring states how the
shape sits along the body axes. Arguments broadcast over leading batch dimensions.

Errors: :func:`validate` raises ``ValueError`` naming the violated condition and the
offending values (it needs concrete values; under a JAX transformation it falls back to
:func:`check`). :func:`check` is jit-safe: it raises at run time through
``equinox.error_if``. Wrong shapes raise ``ValueError`` naming the expected trailing shape
while tracing. The shape functions and :func:`from_point_masses` / :func:`parallel_axis`
refuse a mass that is not finite and positive (point masses: not negative) and sizes or
positions that are negative or not finite (``ValueError`` for concrete values,
``equinox.error_if`` under ``jit``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid import quaternion as quat
from jrigid._checks import as_float, check_shape, fail_if, is_traced

__all__ = [
    "box",
    "check",
    "conditions",
    "disk",
    "ellipsoid",
    "from_point_masses",
    "parallel_axis",
    "principal_axes",
    "rotate_tensor",
    "rotate_tensor_by_matrix",
    "solid_cylinder",
    "sphere",
    "t_handle_moments",
    "t_handle_parts",
    "thin_disk",
    "thin_plate",
    "thin_rod",
    "to_tensor",
    "validate",
]


def _mass(m, name: str = "mass") -> jax.Array:
    m = as_float(m)
    return fail_if(
        m, ~(jnp.isfinite(m) & (m > 0)), f"{name} must be finite and > 0", lambda: f"{m}"
    )


def _size(x, name: str) -> jax.Array:
    x = as_float(x)
    return fail_if(
        x, ~(jnp.isfinite(x) & (x >= 0)), f"{name} must be finite and >= 0", lambda: f"{x}"
    )


def _body(m, **sizes) -> list[jax.Array]:
    """Checked mass and sizes of a shape, broadcast to one batch shape."""
    checked = [_mass(m), *(_size(v, k) for k, v in sizes.items())]
    return jnp.broadcast_arrays(*checked)


def _moments(*columns) -> jax.Array:
    """Stack three broadcast-compatible ``(...)`` arrays into ``(..., 3)``."""
    return jnp.stack(jnp.broadcast_arrays(*[as_float(c) for c in columns]), axis=-1)


def _eye(like: jax.Array) -> jax.Array:
    """Identity ``(..., 3, 3)`` with the batch shape and dtype of ``like (..., 3)``."""
    return jnp.broadcast_to(jnp.eye(3, dtype=like.dtype), like.shape[:-1] + (3, 3))


def _check_tensor(inertia: jax.Array, name: str = "inertia") -> None:
    hint = ""
    if inertia.ndim >= 1 and inertia.shape[-1] == 3 and inertia.shape[-2:] != (3, 3):
        hint = " (a tensor; use to_tensor for principal moments)"
    check_shape(inertia, name, (3, 3), why=hint)


def _check_moments(moments: jax.Array, name: str = "moments") -> None:
    check_shape(moments, name, (3,))


# --------------------------------------------------------------------------- Table 17.1


def ellipsoid(m, a, b, c) -> jax.Array:
    """Solid ellipsoid with semi-axes ``a, b, c`` along body ``x, y, z`` (Table 17.1).

    Args:
        m: mass ``(...)``.
        a, b, c: semi-axes ``(...)`` (the table's "axes (2a, 2b, 2c)").

    Returns:
        ``(..., 3)``: ``m (b²+c², a²+c², a²+b²) / 5``.
    """
    m, a, b, c = _body(m, a=a, b=b, c=c)
    a2, b2, c2 = a * a, b * b, c * c
    return _moments(m * (b2 + c2) / 5, m * (a2 + c2) / 5, m * (a2 + b2) / 5)


def box(m, a, b, c) -> jax.Array:
    """Solid rectangular box (the table's parallelepiped), sides ``a, b, c`` along ``x, y, z``.

    Args:
        m: mass ``(...)``.
        a, b, c: full side lengths ``(...)``.

    Returns:
        ``(..., 3)``: ``m (b²+c², a²+c², a²+b²) / 12`` (Table 17.1).
    """
    m, a, b, c = _body(m, a=a, b=b, c=c)
    a2, b2, c2 = a * a, b * b, c * c
    return _moments(m * (b2 + c2) / 12, m * (a2 + c2) / 12, m * (a2 + b2) / 12)


def sphere(m, r) -> jax.Array:
    """Solid sphere of radius ``r``: ``(2/5) m r²`` about every diameter (Table 17.1).

    Args:
        m: mass ``(...)``.
        r: radius ``(...)``.

    Returns:
        ``(..., 3)``.
    """
    m, r = _body(m, r=r)
    i = 0.4 * m * r * r
    return _moments(i, i, i)


def thin_rod(m, length) -> jax.Array:
    """Thin rod of length ``length`` along body ``z`` (Table 17.1).

    Args:
        m: mass ``(...)``.
        length: ``(...)``.

    Returns:
        ``(..., 3)``: ``(m l²/12, m l²/12, 0)``. The zero moment makes the rod a
        degenerate body: :func:`validate` rejects it as not positive definite.
    """
    m, length = _body(m, length=length)
    i = m * length * length / 12
    return _moments(i, i, jnp.zeros_like(i))


def thin_disk(m, r) -> jax.Array:
    """Thin circular sheet of radius ``r`` with its normal along body ``z`` (Table 17.1).

    Args:
        m: mass ``(...)``.
        r: radius ``(...)``.

    Returns:
        ``(..., 3)``: ``(m r²/4, m r²/4, m r²/2)``.
    """
    m, r = _body(m, r=r)
    i = m * r * r / 4
    return _moments(i, i, 2 * i)


def thin_plate(m, a, b) -> jax.Array:
    """Thin rectangular sheet, side ``a`` along body ``x``, ``b`` along ``y``, normal ``z``.

    Table 17.1 prints the normal moment as ``m(a²+b²)/2``; the integral 17.31c gives
    ``m(a²+b²)/12`` (the perpendicular-axis theorem ``I3 = I1 + I2`` agrees).

    Args:
        m: mass ``(...)``.
        a, b: side lengths ``(...)``.

    Returns:
        ``(..., 3)``: ``(m b²/12, m a²/12, m (a²+b²)/12)``.
    """
    m, a, b = _body(m, a=a, b=b)
    ix, iy = m * b * b / 12, m * a * a / 12
    return _moments(ix, iy, ix + iy)


def solid_cylinder(m, r, h) -> jax.Array:
    """Solid circular cylinder of radius ``r`` and height ``h``, axis along body ``z``.

    Args:
        m: mass ``(...)``.
        r: radius ``(...)``.
        h: height ``(...)``.

    Returns:
        ``(..., 3)``: ``(m(3r²+h²)/12, m(3r²+h²)/12, m r²/2)`` (17.31 integrated).
    """
    m, r, h = _body(m, r=r, h=h)
    i = m * (3 * r * r + h * h) / 12
    return _moments(i, i, m * r * r / 2)


def disk(m, r, thickness) -> jax.Array:
    """Disk of finite ``thickness`` with its normal along body ``z``; a short cylinder.

    Args:
        m: mass ``(...)``.
        r: radius ``(...)``.
        thickness: ``(...)``.

    Returns:
        ``(..., 3)``, equal to ``solid_cylinder(m, r, thickness)``; tends to
        :func:`thin_disk` as ``thickness → 0``.
    """
    return solid_cylinder(m, r, thickness)


def t_handle_parts(
    bar_length=1.0, bar_radius=0.08, stem_length=0.7, stem_radius=0.06
) -> list[dict]:
    """The two solid cylinders of a T-handle (Dzhanibekov's wing nut), centred on its
    centre of mass.

    The bar (the cross-piece) lies along body ``x``; the stem along ``+y`` starts at the
    bar's surface (``y = bar_radius`` before centring), so the parts do not overlap and a
    uniform density gives the mass fractions as volume fractions. Mirror symmetry in ``x``
    and ``z`` makes ``x, y, z`` the principal axes. :func:`jrigid.viz.t_handle` draws it.

    Args:
        bar_length, bar_radius, stem_length, stem_radius: ``()`` sizes.

    Returns:
        two dicts (bar, stem) with ``radius``, ``length``, ``center (3,)`` (from the
        common centre of mass), ``orientation (4,)`` (the quaternion turning a cylinder
        along ``z`` onto the part's axis) and ``mass_fraction``.
    """
    v_bar = jnp.pi * as_float(bar_radius) ** 2 * bar_length
    v_stem = jnp.pi * as_float(stem_radius) ** 2 * stem_length
    total = v_bar + v_stem
    y_stem = bar_radius + as_float(stem_length) / 2
    y_cm = v_stem * y_stem / total
    zero = jnp.zeros_like(y_cm)
    z_to_x = quat.from_axis_angle(jnp.array([0.0, 1.0, 0.0]), jnp.pi / 2)
    z_to_y = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), -jnp.pi / 2)
    return [
        dict(radius=bar_radius, length=bar_length, center=jnp.stack([zero, -y_cm, zero]),
             orientation=z_to_x, mass_fraction=v_bar / total),
        dict(radius=stem_radius, length=stem_length,
             center=jnp.stack([zero, y_stem - y_cm, zero]), orientation=z_to_y,
             mass_fraction=v_stem / total),
    ]  # fmt: skip


def t_handle_moments(mass=1.0, **dims) -> jax.Array:
    """Principal moments of the T-handle of :func:`t_handle_parts` about body ``x, y, z``.

    Each solid cylinder's central tensor (:func:`solid_cylinder`) is turned onto its axis
    (:func:`rotate_tensor`) and shifted to the common centre of mass
    (:func:`parallel_axis`). By the body's mirror symmetries the sum is diagonal.

    Args:
        mass: ``()`` total mass.
        dims: the sizes of :func:`t_handle_parts`.

    Returns:
        ``(3,)`` moments (the middle one, about the stem's ``y``, is the intermediate).

    Raises:
        ValueError: (concrete input) if the tensor is not diagonal.

    Example:
        >>> from jrigid import inertia
        >>> m = inertia.t_handle_moments(1.0)
        >>> print(bool(m[0] < m[1] < m[2]))
        True
    """
    total = jnp.zeros((3, 3))
    for part in t_handle_parts(**dims):
        m = as_float(mass) * part["mass_fraction"]
        central = to_tensor(solid_cylinder(m, part["radius"], part["length"]))
        total = total + parallel_axis(rotate_tensor(central, part["orientation"]), m,
                                      part["center"])  # fmt: skip
    if not is_traced(total):
        off = jnp.abs(total - jnp.diag(jnp.diag(total))).max()
        if off > 1e-9 * jnp.abs(total).max():
            raise ValueError(f"T-handle tensor is not diagonal (off-diagonal {float(off):.3g})")
    return jnp.diag(total)


# --------------------------------------------------------------------------- tensors


def to_tensor(moments) -> jax.Array:
    """Diagonal tensor ``diag(I1, I2, I3)`` from principal moments.

    Args:
        moments: ``(..., 3)``.

    Returns:
        ``(..., 3, 3)``.
    """
    moments = as_float(moments)
    _check_moments(moments)
    return moments[..., :, None] * _eye(moments)


def from_point_masses(masses, positions, origin=None) -> jax.Array:
    """Inertia tensor of point masses about ``origin`` (the sums behind 17.31).

    ``I = Σ_k m_k (|r_k|² 1 − r_k r_kᵀ)`` with ``r_k = position_k − origin``; its diagonal
    is 17.31a–c with the integrals replaced by sums, the off-diagonal entries are the
    products of inertia.

    Args:
        masses: ``(..., N)``, finite and ``>= 0``.
        positions: ``(..., N, 3)``, finite.
        origin: ``(..., 3)``; default the centre of mass (then the total mass must be
            ``> 0``).

    Returns:
        ``(..., 3, 3)``.
    """
    masses, positions = as_float(masses), as_float(positions)
    if positions.ndim < 2 or positions.shape[-1] != 3:
        raise ValueError(f"positions must have shape (..., N, 3); got shape {positions.shape}")
    n = positions.shape[-2]
    check_shape(masses, "masses", (n,), why=f" to match positions of shape {positions.shape}")
    masses = _size(masses, "masses")
    positions = fail_if(positions, ~jnp.isfinite(positions), "positions must be finite")
    if origin is None:
        masses = fail_if(
            masses,
            ~(jnp.sum(masses, axis=-1) > 0),
            "masses must not all be zero (the centre of mass is undefined)",
        )
    batch = jnp.broadcast_shapes(masses.shape[:-1], positions.shape[:-2])
    masses = jnp.broadcast_to(masses, batch + (n,))
    positions = jnp.broadcast_to(positions, batch + (n, 3))
    if origin is None:
        origin = jnp.einsum("...n,...ni->...i", masses, positions) / jnp.sum(
            masses, axis=-1, keepdims=True
        )
    else:
        origin = as_float(origin)
        check_shape(origin, "origin", (3,))
        batch = jnp.broadcast_shapes(batch, origin.shape[:-1])
        masses = jnp.broadcast_to(masses, batch + (n,))
        positions = jnp.broadcast_to(positions, batch + (n, 3))
        origin = jnp.broadcast_to(origin, batch + (3,))
    r = positions - origin[..., None, :]
    second = jnp.einsum("...n,...ni,...nj->...ij", masses, r, r)
    trace = jnp.trace(second, axis1=-2, axis2=-1)
    return trace[..., None, None] * _eye(second[..., 0]) - second


def parallel_axis(I_cm, mass, d) -> jax.Array:
    """Shift a centre-of-mass tensor to a point displaced by ``d`` (parallel-axis theorem).

    ``I_O = I_cm + M (|d|² 1 − d dᵀ)``; the sign of ``d`` does not matter.

    Args:
        I_cm: ``(..., 3, 3)`` about the centre of mass.
        mass: total mass ``(...)``, finite and ``> 0``.
        d: displacement between the centre of mass and the new origin ``(..., 3)``.

    Returns:
        ``(..., 3, 3)``.
    """
    I_cm, mass, d = as_float(I_cm), _mass(mass), as_float(d)
    _check_tensor(I_cm, "I_cm")
    check_shape(d, "d", (3,))
    batch = jnp.broadcast_shapes(I_cm.shape[:-2], mass.shape, d.shape[:-1])
    I_cm = jnp.broadcast_to(I_cm, batch + (3, 3))
    mass = jnp.broadcast_to(mass, batch)
    d = jnp.broadcast_to(d, batch + (3,))
    dd = d[..., :, None] * d[..., None, :]
    shift = jnp.sum(d * d, axis=-1)[..., None, None] * _eye(d) - dd
    return I_cm + mass[..., None, None] * shift


def rotate_tensor_by_matrix(inertia, R) -> jax.Array:
    """Frame change ``R I Rᵀ`` (17.32, where the chapter writes ``M I M⁻¹``).

    With ``R`` the active body → space matrix (``v_space = R v_body``), this turns a
    body-frame tensor into the space-frame one.

    Args:
        inertia: ``(..., 3, 3)``.
        R: ``(..., 3, 3)`` rotation matrix.

    Returns:
        ``(..., 3, 3)``.
    """
    inertia, R = as_float(inertia), as_float(R)
    _check_tensor(inertia)
    _check_tensor(R, "R")
    return R @ inertia @ jnp.swapaxes(R, -1, -2)


def rotate_tensor(inertia, q) -> jax.Array:
    """Body → space frame change of an inertia tensor, ``R I Rᵀ`` with ``R`` from ``q`` (17.32).

    Args:
        inertia: ``(..., 3, 3)`` in the body frame (use :func:`to_tensor` for moments).
        q: ``(..., 4)`` unit quaternion, body → space.

    Returns:
        ``(..., 3, 3)`` in the space frame. ``rotate_tensor(I, quat.conjugate(q))`` goes back.
    """
    return rotate_tensor_by_matrix(inertia, quat.to_matrix(q))


@jax.custom_jvp
def _eigh(sym):
    """``(w, V)`` of ``jnp.linalg.eigh``, with a derivative that is finite at repeated ``w``."""
    w, v = jnp.linalg.eigh(sym)
    return w, v


@_eigh.defjvp
def _eigh_jvp(primals, tangents):
    # A V = V Λ gives dΛ = diag(P) and dV = V (F ∘ P), P = Vᵀ dA V, F_ij = 1/(λ_j − λ_i).
    # For λ_i = λ_j (to within rounding: 64 eps of the largest) the pair's rotation within
    # the eigenspace is arbitrary; it is taken as zero (jnp.linalg.eigh's own rule divides
    # by the rounding-level gap there and returns NaN or noise).
    (sym,), (dsym,) = primals, tangents
    w, v = _eigh(sym)
    proj = jnp.swapaxes(v, -1, -2) @ dsym @ v
    gap = w[..., None, :] - w[..., :, None]
    tol = 64 * jnp.finfo(w.dtype).eps * jnp.max(jnp.abs(w), axis=-1)[..., None, None]
    apart = jnp.abs(gap) > tol
    f = jnp.where(apart, 1.0 / jnp.where(apart, gap, 1.0), 0.0)
    dw = jnp.diagonal(proj, axis1=-2, axis2=-1)
    return (w, v), (dw, v @ (f * proj))


def principal_axes(inertia) -> tuple[jax.Array, jax.Array]:
    """Principal moments and a right-handed principal frame of a symmetric tensor.

    ``I = R diag(moments) Rᵀ`` with ``R = quaternion.to_matrix(q)``: the columns of ``R``
    are the principal axes in the frame of ``I``, and ``q`` is the body → frame rotation.

    For repeated moments (equal to within 64 machine epsilons of the largest) any
    orthonormal basis of the eigenspace is equally valid and one is returned; the moments
    and their gradients stay well defined there, and the frame's gradient is finite: it
    leaves out the (arbitrary) rotation within the eigenspace, so that any function of
    ``R diag(moments) Rᵀ`` gets its derivative except for perturbations that mix two axes
    of equal moment.

    Args:
        inertia: ``(..., 3, 3)`` symmetric (the symmetric part is used).

    Returns:
        ``(moments, q)``: ``moments (..., 3)`` in ascending order, ``q (..., 4)``.
    """
    inertia = as_float(inertia)
    _check_tensor(inertia)
    sym = 0.5 * (inertia + jnp.swapaxes(inertia, -1, -2))
    moments, V = _eigh(sym)
    sign = jnp.sign(jnp.linalg.det(V))
    sign = jnp.where(sign == 0, 1.0, sign).astype(V.dtype)
    V = jnp.concatenate([V[..., :2], V[..., 2:] * sign[..., None, None]], axis=-1)
    return moments, quat.from_matrix(V)


# --------------------------------------------------------------------------- checks


def _kind(inertia: jax.Array, kind: str | None) -> str:
    if kind is None:
        kind = "tensor" if inertia.ndim >= 2 and inertia.shape[-2:] == (3, 3) else "moments"
    if kind == "tensor":
        _check_tensor(inertia)
    elif kind == "moments":
        _check_moments(inertia)
    else:
        raise ValueError(f"kind must be None, 'moments' or 'tensor', got {kind!r}")
    return kind


def _conditions(inertia: jax.Array, kind: str, allow_nonphysical: bool, rtol):
    """``[(name, bad (...), label, values), ...]`` in the order they are reported."""
    eps = jnp.finfo(inertia.dtype).eps
    rtol = jnp.sqrt(eps) if rtol is None else rtol
    core = (-2, -1) if kind == "tensor" else (-1,)
    finite = jnp.all(jnp.isfinite(inertia), axis=core)
    clean = jnp.where(jnp.isfinite(inertia), inertia, 0.0)
    out = [("values not finite", ~finite, "values", inertia)]
    ok = finite  # each element is reported under its first failed condition only
    if kind == "tensor":
        scale = jnp.max(jnp.abs(clean), axis=core)
        asym = jnp.max(jnp.abs(clean - jnp.swapaxes(clean, -1, -2)), axis=core)
        symmetric = asym <= rtol * scale
        out.append(("tensor not symmetric", ok & ~symmetric, "tensor", inertia))
        ok = ok & symmetric
        sym = 0.5 * (clean + jnp.swapaxes(clean, -1, -2))
        moments = jnp.linalg.eigvalsh(sym)
        pd = _positive_definite(sym)
    else:
        moments = jnp.sort(clean, axis=-1)
        pd = moments[..., 0] > 0  # exact: the moments are given
    lo, mid, hi = moments[..., 0], moments[..., 1], moments[..., 2]
    out.append(("not positive definite", ok & ~pd, "principal moments", moments))
    ok = ok & pd
    if not allow_nonphysical:
        tri = lo + mid >= hi * (1 - rtol)
        out.append(
            (
                "triangle inequality Ia + Ib >= Ic violated",
                ok & ~tri,
                "principal moments",
                moments,
            )
        )
    return out


def _positive_definite(sym: jax.Array) -> jax.Array:
    """Whether a symmetric ``(..., 3, 3)`` is positive definite, independent of units.

    The test runs on ``D^-1/2 I D^-1/2`` (``D`` the diagonal), which is positive definite
    exactly when ``I`` is and whose eigenvalues lie in ``[0, 3]`` whatever the scale of
    each axis, so a needle such as ``diag(1e-12, 1e12, 1e12)`` passes: its smallest
    moment is not compared with the largest. The smallest scaled eigenvalue must exceed
    its rounding error, ``3 eps`` times the largest.
    """
    eps = jnp.finfo(sym.dtype).eps
    d = jnp.diagonal(sym, axis1=-2, axis2=-1)
    positive = jnp.all(d > 0, axis=-1)
    r = jax.lax.rsqrt(jnp.where(d > 0, d, jnp.ones_like(d)))
    scaled = sym * r[..., :, None] * r[..., None, :]
    ev = jnp.linalg.eigvalsh(scaled)
    return positive & (ev[..., 0] > 3 * eps * ev[..., -1])


def conditions(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """The checks of :func:`validate` as traced flags: ``[(name, bad, label, values), ...]``.

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical, kind, rtol: as :func:`validate`.

    Returns:
        One entry per condition, in report order: its name, ``bad (...)`` (batch
        shape), and the label and values a message would quote.
    """
    inertia = as_float(inertia)
    return _conditions(inertia, _kind(inertia, kind), allow_nonphysical, rtol)


def check(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """Jit-safe version of :func:`validate`: returns ``inertia``, errors at run time.

    Uses ``equinox.error_if``; under ``jax.jit`` a violated condition raises a runtime
    error whose message names the condition (values are not available there).

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical: skip the triangle inequality.
        kind: ``"moments"``, ``"tensor"`` or ``None`` (a trailing ``(3, 3)`` means tensor).
        rtol: relative tolerance of the symmetry and triangle tests; default ``sqrt(eps)``.

    Returns:
        ``inertia`` unchanged (as a float array).
    """
    inertia = as_float(inertia)
    kind = _kind(inertia, kind)
    for name, bad, _, _ in _conditions(inertia, kind, allow_nonphysical, rtol):
        inertia = eqx.error_if(inertia, bad, f"inertia is not valid: {name}")
    return inertia


def validate(inertia, *, allow_nonphysical: bool = False, kind: str | None = None, rtol=None):
    """Check that ``inertia`` is a physical inertia; raise ``ValueError`` otherwise.

    Conditions, in order: finite; symmetric (tensor only, ``|I − Iᵀ| ≤ rtol·max|I|``);
    positive definite (moments: the smallest ``> 0``; tensor: positive diagonal and,
    after scaling to unit diagonal, the smallest eigenvalue above its rounding error
    ``3 eps ×`` the largest; both tests are independent of the units of each axis, so
    ``(1e-12, 1e12, 1e12)``, a needle, is accepted); triangle inequality
    ``Ia + Ib ≥ Ic (1 − rtol)`` of the principal moments, which every real mass
    distribution satisfies (skipped with ``allow_nonphysical=True``, e.g. for the
    Hairer–Lubich–Wanner test body ``(2, 1, 2/3)``). Flat bodies meet it with equality.

    Each batch element is reported under the first condition it violates (a
    non-symmetric tensor as "not symmetric", never as "not positive definite"). The
    message names the first violated condition, the first offending batch index and
    its values. Under a JAX transformation (jit, vmap, grad) this defers to :func:`check`.

    Args:
        inertia: moments ``(..., 3)`` or tensor ``(..., 3, 3)``.
        allow_nonphysical: skip the triangle inequality.
        kind: ``"moments"``, ``"tensor"`` or ``None`` (a trailing ``(3, 3)`` means tensor;
            pass ``"moments"`` for a batch of three moment vectors).
        rtol: relative tolerance of the symmetry and triangle tests; default ``sqrt(eps)``.

    Returns:
        ``inertia`` unchanged (as a float array).
    """
    inertia = as_float(inertia)
    kind = _kind(inertia, kind)
    if is_traced(inertia):
        return check(inertia, allow_nonphysical=allow_nonphysical, kind=kind, rtol=rtol)
    for name, bad, label, values in _conditions(inertia, kind, allow_nonphysical, rtol):
        if bool(jnp.any(bad)):
            where = ""
            if bad.ndim:
                idx = tuple(int(i) for i in jnp.argwhere(bad)[0])
                values = values[idx]
                where = f" at batch index {idx}"
            raise ValueError(f"inertia is not valid: {name}{where}; {label} {values}")
    return inertia
