"""Principal moments of uniform solids (Table 17.1) and the two-cylinder T-handle."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jrigid import quaternion as quat
from jrigid._checks import as_float, as_floats, is_traced

from ._checks import _mass, _size
from ._tensors import parallel_axis, rotate_tensor, to_tensor

__all__ = [
    "ellipsoid",
    "box",
    "sphere",
    "thin_rod",
    "thin_disk",
    "thin_plate",
    "solid_cylinder",
    "disk",
    "t_handle_parts",
    "t_handle_moments",
]






def _body(m, **sizes) -> list[jax.Array]:
    """Checked mass and sizes of a shape, broadcast to one batch shape."""
    checked = [_mass(m), *(_size(v, k) for k, v in sizes.items())]
    return as_floats(*checked, broadcast=True)


def _moments(*columns) -> jax.Array:
    """Stack three broadcast-compatible ``(...)`` arrays into ``(..., 3)``."""
    return jnp.stack(as_floats(*columns, broadcast=True), axis=-1)


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
        bar_length, bar_radius, stem_length, stem_radius: ``(...)`` sizes, finite and
            ``> 0``, broadcast together to the batch shape ``(...)``.

    Returns:
        two dicts (bar, stem) with ``radius (...)``, ``length (...)``, ``center (..., 3)``
        (from the common centre of mass), ``orientation (..., 4)`` (the quaternion turning
        a cylinder along ``z`` onto the part's axis) and ``mass_fraction (...)``.

    Raises:
        ValueError: a size that is not finite and ``> 0``.
    """
    sizes = dict(bar_length=bar_length, bar_radius=bar_radius, stem_length=stem_length,
                 stem_radius=stem_radius)  # fmt: skip
    bar_length, bar_radius, stem_length, stem_radius = as_floats(
        *(_mass(v, k) for k, v in sizes.items()), broadcast=True
    )
    v_bar = jnp.pi * bar_radius**2 * bar_length
    v_stem = jnp.pi * stem_radius**2 * stem_length
    total = v_bar + v_stem
    y_stem = bar_radius + stem_length / 2
    y_cm = v_stem * y_stem / total
    zero = jnp.zeros_like(y_cm)

    def turn(axis, angle):
        q = quat.from_axis_angle(jnp.array(axis, dtype=y_cm.dtype), angle)
        return jnp.broadcast_to(q, y_cm.shape + (4,))

    return [
        dict(radius=bar_radius, length=bar_length,
             center=jnp.stack([zero, -y_cm, zero], axis=-1),
             orientation=turn([0.0, 1.0, 0.0], jnp.pi / 2), mass_fraction=v_bar / total),
        dict(radius=stem_radius, length=stem_length,
             center=jnp.stack([zero, y_stem - y_cm, zero], axis=-1),
             orientation=turn([1.0, 0.0, 0.0], -jnp.pi / 2), mass_fraction=v_stem / total),
    ]  # fmt: skip


def t_handle_moments(mass=1.0, **dims) -> jax.Array:
    """Principal moments of the T-handle of :func:`t_handle_parts` about body ``x, y, z``.

    Each solid cylinder's central tensor (:func:`solid_cylinder`) is turned onto its axis
    (:func:`rotate_tensor`) and shifted to the common centre of mass
    (:func:`parallel_axis`). By the body's mirror symmetries the sum is diagonal.

    Args:
        mass: ``(...)`` total mass, finite and ``> 0``.
        dims: the ``(...)`` sizes of :func:`t_handle_parts` (keywords).

    Returns:
        ``(..., 3)`` moments (the middle one, about the stem's ``y``, is the intermediate
        for the default sizes).

    Raises:
        ValueError: a mass or size that is not finite and ``> 0``; (concrete input) a
            tensor that is not diagonal.

    Example:
        >>> from jrigid import inertia
        >>> m = inertia.t_handle_moments(1.0)
        >>> print(bool(m[0] < m[1] < m[2]))
        True
    """
    mass = _mass(mass)
    # the dtype of the inputs (a float32 mass with the default sizes stays float32)
    dtype = jnp.result_type(mass, *(as_float(v, weak=True) for v in dims.values()))
    total = 0.0
    for part in t_handle_parts(**dims):
        m = jnp.multiply(*jnp.broadcast_arrays(mass, part["mass_fraction"]))
        central = to_tensor(solid_cylinder(m, part["radius"], part["length"]))
        total = total + parallel_axis(rotate_tensor(central, part["orientation"]), m,
                                      part["center"])  # fmt: skip
    diagonal = jnp.diagonal(total, axis1=-2, axis2=-1)
    if not is_traced(total):
        off = jnp.abs(total * jnp.broadcast_to(1 - jnp.eye(3), total.shape)).max(axis=(-2, -1))
        ratio = float(jnp.max(off / jnp.abs(total).max(axis=(-2, -1))))
        if ratio > 1e-9:
            raise ValueError(f"T-handle tensor is not diagonal (off-diagonal {ratio:.3g})")
    return diagonal.astype(dtype)
