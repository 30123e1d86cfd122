# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # First steps through the chapter
#
# This tutorial walks through the chapter *Visualization and Rigid Body Dynamics* with
# jrigid: affine maps and quaternions (17.1–17.28), an inertia tensor (17.29–17.32), a
# free rotor integrated from Euler's equations in quaternion form (17.35, 17.42–17.50),
# drawn in the space and body frames, and the Dzhanibekov flip of a T-handle spun about
# its intermediate axis, timed against the closed form.
#
# Everything is a pure JAX function of arrays: it works under `jit`, `vmap` and `grad`,
# on any leading batch shape. float64 is jrigid's recommended mode.
#
# The page is executed when the site is built. `JRIGID_DOCS_QUICK=1` runs it with
# fewer samples.

# %%
# %matplotlib inline
import os

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

import jrigid
from jrigid import affine, exact, inertia, initial, stability, theory, viz
from jrigid import quaternion as quat

QUICK = os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")
SAMPLES = 601 if QUICK else 2001

# %% [markdown]
# ## Points, vectors and homogeneous coordinates (17.1–17.7)
#
# A homogeneous 2D transform is a 3×3 matrix `[A d; 0 1]` (17.7). Points carry `w = 1`
# and are translated; vectors carry `w = 0` and are not. Rotating a triangle by 30°
# about one of its vertices keeps that vertex fixed (Exercise 17.2b):

# %%
triangle = jnp.array([[1.0, 0.0], [2.0, 0.0], [1.5, 1.0]])
R = affine.rotation_2d(jnp.deg2rad(30.0), pivot=triangle[0])
turned = affine.apply_to_points(R, triangle)
arrow = jnp.array([1.0, 0.0])
print("vertex 0 before and after:", triangle[0], turned[0])
print("a vector is only rotated:", affine.apply_to_vectors(R, arrow))

fig = viz.new_figure(figsize=(12, 4), dpi=110)
ax = fig.add_subplot(1, 2, 1)
for pts, style, label in ((triangle, "C0-", "before"), (turned, "C1-", "after")):
    closed = np.vstack([pts, pts[:1]])
    ax.plot(closed[:, 0], closed[:, 1], style, marker="o", label=label)
ax.set_aspect("equal")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_title("rotation by 30° about vertex 0")
ax.legend()
ax = fig.add_subplot(1, 2, 2)
S = affine.scaling(jnp.array([2.0, 1.0]))
for M, label in ((R @ S, "rotate after scaling"), (S @ R, "scale after rotating")):
    pts = np.asarray(affine.apply_to_points(M, triangle))
    closed = np.vstack([pts, pts[:1]])
    ax.plot(closed[:, 0], closed[:, 1], marker="o", label=label)
ax.set_aspect("equal")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_title("rotation and scaling do not commute")
ax.legend()
fig

# %% [markdown]
# ## Quaternions (17.18–17.28)
#
# A rotation by θ about the unit axis `u` is the unit quaternion
# `(cos θ/2, u sin θ/2)` (17.25), stored scalar first, `(w, x, y, z)`. It rotates a
# vector by `q (0, v) q*` (17.26). Hamilton's product (17.24) composes rotations:
# `multiply(p, q)` turns by `q` first, then by `p`, and the order matters.

# %%
qz = quat.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), jnp.pi / 2)  # 90° about z
qx = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.pi / 2)  # 90° about x
v = jnp.array([1.0, 0.0, 0.0])
print("z-turn of x:          ", quat.rotate(qz, v))
print("x then z:             ", quat.rotate(quat.multiply(qz, qx), v))
print("z then x:             ", quat.rotate(quat.multiply(qx, qz), v))
axis, angle = quat.to_axis_angle(quat.multiply(qz, qx))  # (17.27)
print("composite axis, angle:", axis, np.degrees(angle))

# %% [markdown]
# jrigid's matrices are *active* (`v_space = R v_body`, the same as scipy's
# `Rotation.as_matrix`); the chapter's (17.28) is the passive matrix, the transpose.
# Rodrigues' formula (17.16–17.17) gives the same matrix from the axis and angle:

# %%
q = quat.multiply(qz, qx)
R_active = quat.to_matrix(q)
print("passive (17.28) == active transposed:", bool(jnp.allclose(quat.passive_matrix(q), R_active.T)))
print("Rodrigues (17.17) == active:         ", bool(jnp.allclose(quat.rodrigues_matrix(axis, angle), R_active)))

# %% [markdown]
# ## An inertia tensor (17.29–17.32)
#
# A box of mass 1 and sides `(1, 2, 3)` has principal moments `m(b² + c²)/12, …`
# (Table 17.1). Turned by a rotation `R`, its tensor in the space frame is `R I Rᵀ`
# (17.32); `principal_axes` recovers the moments and the rotation.

# %%
moments = inertia.box(1.0, 1.0, 2.0, 3.0)
print("principal moments:", moments)
tensor = inertia.rotate_tensor(jnp.diag(moments), q)
print("space-frame tensor:\n", np.round(tensor, 4))
back, q_back = inertia.principal_axes(tensor)
print("moments recovered:", back)

# %% [markdown]
# ## A free rotor (17.35, 17.42–17.50)
#
# A scene is a body, how it is held (default: free rotation about the centre of mass)
# and what acts on it (nothing here). The state is `(q, q̇)`; `initial.from_omega` builds
# it from the body angular velocity. `jrigid.simulate` integrates Euler's equations in
# quaternion-acceleration form (17.50) with an adaptive Runge–Kutta pair and projects
# the state back onto `|q| = 1`, `q·q̇ = 0` and the conserved energy and `|L|` after
# every step.

# %%
body = jrigid.RigidBody(moments)
scene = jrigid.Scene(body, jrigid.FreeRotation())
state = initial.from_omega(omega=jnp.array([0.4, 0.2, 2.0]))  # near axis 3, the smallest moment
ts = jnp.linspace(0.0, 20.0, SAMPLES)
traj = jrigid.simulate(scene, state, ts)
print("steps:", int(traj.stats["num_steps"]), " result:", jrigid.Result(int(traj.result)).name)
E, L = traj.energy, jnp.linalg.norm(traj.L_space, axis=-1)
print(f"energy drift {float(jnp.max(jnp.abs(E / E[0] - 1))):.1e}, |L| drift {float(jnp.max(jnp.abs(L / L[0] - 1))):.1e}")

# %%
fig = viz.new_figure(figsize=(11, 3.6), dpi=110)
viz.plot_omega(traj, ax=fig.add_subplot(1, 2, 1))
viz.plot_invariants(traj, ax=fig.add_subplot(1, 2, 2))
for ax in fig.axes:
    ax.set_xlabel("t (s)")
fig.axes[0].set_ylabel("body ω (rad/s)", rotation=90)
fig

# %% [markdown]
# The same motion drawn: the box in the space frame, where `L` (orange) stays fixed and
# the body axes wobble about it, and in the body frame, where `ω` and `L` trace
# closed curves (polhodes) about axis 3, the axis of smallest moment (as stable as the
# largest: only the intermediate axis is not).

# %%
fig = viz.space_body_views(traj, viz.box(1.0, 2.0, 3.0), trail=SAMPLES // 4, figsize=(11, 5.5), dpi=110)
fig

# %% [markdown]
# ## The Dzhanibekov flip (Problem 17.3)
#
# Spun about its *intermediate* axis, a body turns over again and again. The T-handle
# of the demo (two cylinders) spins at 1.5 Hz about that axis, tilted by 1° toward the
# largest one. Every sign change of the body `ω` along the spin axis is a flip; the
# closed-form solution (`jrigid.exact`, Jacobi elliptic functions) says they come every
# half period `2K(m)/λ`, and near the separatrix `≈ (2/λ) ln(C/ε)`.

# %%
t_moments = inertia.t_handle_moments()
mid = int(np.argsort(np.asarray(t_moments))[1])
big = int(np.argmax(np.asarray(t_moments)))
speed = 2 * jnp.pi * 1.5
tilts = jnp.deg2rad(jnp.logspace(-3, 1, 41))  # 0.001° ... 10°, 1° among them


def spin(eps):
    """ω0: |ω| = speed about the intermediate axis, tilted by eps toward the largest."""
    e = jnp.asarray(eps)[..., None]
    return speed * (jnp.cos(e) * jnp.eye(3)[mid] + jnp.sin(e) * jnp.eye(3)[big])


# The closed form for every tilt at once (batch dimensions broadcast).
consts = exact.prepare(t_moments, quat.identity((tilts.size,)), spin(tilts))
exact_half = exact.omega_period(consts) / 2
asymptote, lam, _ = theory.flip_interval_asymptotic(t_moments, speed, tilts)
one = int(jnp.argmin(jnp.abs(tilts - jnp.deg2rad(1.0))))
eps, half_period = tilts[one], float(exact_half[one])
omega0 = spin(eps)

t_handle = jrigid.Scene(jrigid.RigidBody(t_moments))
ts = jnp.linspace(0.0, 4.5 * half_period, SAMPLES)
flip_traj = jrigid.simulate(t_handle, initial.from_omega(omega=omega0), ts)
interval, count = stability.flip_interval(ts, flip_traj.omega[:, mid])
print(f"{int(count)} flips, every {float(interval):.5f} s")
print(f"closed form 2K(m)/λ:        {half_period:.5f} s")
print(f"asymptote (2/λ) ln(C/ε):    {float(asymptote[one]):.5f} s")

# %%
fig = viz.new_figure(figsize=(11, 3.8), dpi=110)
ax = fig.add_subplot(1, 1, 1)
viz.plot_omega(flip_traj, ax=ax)
w, t = np.asarray(flip_traj.omega[:, mid]), np.asarray(ts)
i = np.nonzero(np.sign(w[:-1]) != np.sign(w[1:]))[0]
for crossing in t[i] - w[i] * (t[i + 1] - t[i]) / (w[i + 1] - w[i]):
    ax.axvline(crossing, color="0.6", lw=0.8, ls="--")
ax.set_xlabel("t (s)")
ax.set_ylabel("body ω (rad/s)", rotation=90)
ax.set_title(f"T-handle: ω{mid + 1} changes sign at every flip (dashed), {half_period:.3f} s apart")
fig

# %%
fig = viz.space_body_views(
    flip_traj, viz.t_handle(), index=int(0.55 * (SAMPLES - 1)), trail=SAMPLES // 8,
    figsize=(11, 5.5), dpi=110,
)
fig

# %% [markdown]
# The flip time grows only logarithmically as the tilt shrinks: a tenfold smaller tilt
# adds `(2/λ) ln 10` seconds; the asymptote is good to `O(ε²)`.

# %%
fig = viz.new_figure(figsize=(11, 3.8), dpi=110)
ax = fig.add_subplot(1, 1, 1)
ax.semilogx(np.degrees(tilts), exact_half, "o", ms=4, label="2K(m)/λ (closed form)")
ax.semilogx(np.degrees(tilts), asymptote, "k-", lw=1, label="(2/λ) ln(C/ε)")
ax.set_xlabel("tilt ε from the intermediate axis (degrees)")
ax.set_ylabel("time between flips (s)")
ax.legend()
fig
