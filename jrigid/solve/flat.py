"""A formulation's variables as one flat array inside the solver loop.

diffrax handles the state leaf by leaf: the controller's error norm, the step's
combinations, the saved outputs and the interpolation are separate operations for each
leaf of the state's pytree. A formulation's variables are a pytree of small vectors
(``State(q, q̇)``: two leaves of 4), so a solve on them pays these operations once per
leaf. On XLA:CPU the cost of a loop iteration grows with its operations; with the state
flattened to one array before :func:`diffrax.diffeqsolve` (fastest of repeated runs, rtol
1e-8, the problems of ``benchmarks/speed_vs_error.py``) a step of the heavy top's default
solve costs 0.66 µs instead of 0.75, one of an unprojected free rotor 0.30 µs instead of
0.35; the default free-rotor step, where the projection dominates what is left, is
unchanged (0.40 µs). The error norm, and so the steps, are the same.

:class:`Flat` wraps a formulation for the loop: its vector field, projection and events
take and return the flat array; :meth:`Flat.states` and :meth:`Flat.interpolation` give
the formulation's own pytree back afterwards.
"""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from jrigid._folds import total

__all__ = ["Flat", "vector_lengths"]


def vector_lengths(y):
    """Each vector of a state replaced by its Euclidean length, entry by entry.

    Every leaf of ``y`` is taken as vectors along its last axis (``(4,)``, or ``(N, 4)``
    for a batch): the result has the leaves' shapes, each entry the length of its
    vector. A scalar leaf gives its absolute value.
    """

    def one(a):
        a = jnp.asarray(a)
        if a.ndim == 0:
            return jnp.abs(a)
        return jnp.broadcast_to(jnp.sqrt(total(a * a))[..., None], a.shape)

    return jax.tree_util.tree_map(one, y)


class Flat(eqx.Module):
    """``formulation`` acting on ``ravel(y)``, the concatenated leaves of its variables.

    Build with :meth:`of` from one (unbatched) state of the formulation. The layout
    (tree structure and leaf shapes) is static and hashable, so equal layouts compare
    equal across traces.

    Attributes:
        formulation: the wrapped :class:`~jrigid.formulations.AbstractFormulation`.
        treedef: the variables' tree structure.
        shapes: each leaf's shape, in order.
    """

    formulation: object = eqx.field(static=True)
    treedef: jax.tree_util.PyTreeDef = eqx.field(static=True)
    shapes: tuple[tuple[int, ...], ...] = eqx.field(static=True)

    @classmethod
    def of(cls, formulation, y) -> Flat:
        """The flat layout of ``y``, one state of ``formulation``'s variables."""
        leaves, treedef = jax.tree_util.tree_flatten(y)
        return cls(formulation, treedef, tuple(tuple(jnp.shape(a)) for a in leaves))

    @staticmethod
    def ravel(y) -> jax.Array:
        """``(n,)`` the leaves of one state, concatenated."""
        leaves = jax.tree_util.tree_leaves(y)
        return jnp.concatenate([jnp.ravel(a) for a in leaves])

    @property
    def size(self) -> int:
        """``n``, the length of the flat state."""
        return sum(math.prod(shape) for shape in self.shapes)

    def unravel(self, flat: jax.Array):
        """One state of the formulation's variables from ``flat (n,)``.

        Raises:
            ValueError: ``flat`` is not of shape ``(n,)``.
        """
        if jnp.shape(flat) != (self.size,):
            raise ValueError(
                f"a flat state of this layout has shape ({self.size},), got {jnp.shape(flat)}"
            )
        leaves, start = [], 0
        for shape in self.shapes:
            size = math.prod(shape)
            leaves.append(flat[start:start + size].reshape(shape))
            start += size
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def states(self, ys):
        """The formulation's variables from flat states ``ys (T, n)`` (leading axis kept)."""
        return jax.vmap(self.unravel)(ys)

    def vector_field(self, t, y, scene) -> jax.Array:
        """``d ravel(y)/dt``: the formulation's vector field on the flat state."""
        return self.ravel(self.formulation.vector_field(t, self.unravel(y), scene))

    def lengths(self, y) -> jax.Array:
        """``(n,)`` each entry of ``y`` replaced by the length of its leaf's vector
        (:func:`vector_lengths` of the formulation's variables)."""
        return self.ravel(vector_lengths(self.unravel(y)))

    def project(self, y, scene, invariants=None) -> jax.Array:
        """The formulation's projection on the flat state."""
        return self.ravel(self.formulation.project(self.unravel(y), scene, invariants))

    def event(self, event: diffrax.Event | None) -> diffrax.Event | None:
        """``event`` with its condition functions given the formulation's variables."""
        if event is None:
            return None

        def wrap(fn):
            return lambda t, y, args, **kwargs: fn(t, self.unravel(y), args, **kwargs)

        cond_fn = jax.tree_util.tree_map(wrap, event.cond_fn, is_leaf=callable)
        return diffrax.Event(cond_fn, event.root_finder, event.direction)

    def interpolation(self, interpolation):
        """A dense interpolation of flat states, evaluating to the formulation's variables."""
        return None if interpolation is None else FlatInterpolation(interpolation, self)


class FlatInterpolation(eqx.Module):
    """A diffrax interpolation of a :class:`Flat` solve, giving the formulation's variables.

    Attributes:
        interpolation: diffrax's (``sol.interpolation``) over flat states.
        layout: the :class:`Flat` that unravels them.
    """

    interpolation: diffrax.AbstractPath
    layout: Flat

    @property
    def t0(self):
        return self.interpolation.t0

    @property
    def t1(self):
        return self.interpolation.t1

    def evaluate(self, t0, t1=None, left=True):
        """The state at ``t0`` (or its increment to ``t1``), as diffrax's ``evaluate``."""
        return self.layout.unravel(self.interpolation.evaluate(t0, t1, left))
