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
# # Stability sweeps
#
# Spin a box about its largest or smallest axis and it keeps spinning; spin it near the
# middle axis and it turns over (Problem 17.3). Which directions flip, and how soon? This
# tutorial maps 10⁴ spin directions with `jrigid.ensemble.simulate_many`: one adaptive
# solve per direction, in chunks written to disk as they finish, an interrupted run
# resumed, the map drawn and checked against the closed form, and how to scale the same
# call out to more devices and hosts.
#
# `JRIGID_DOCS_QUICK=1` maps 1000 directions instead of 10⁴.

# %%
# %matplotlib inline
import math
import os
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np

import jrigid
from jrigid import ensemble, inertia, initial, stability
from jrigid.viz import stability as stability_views

QUICK = os.environ.get("JRIGID_DOCS_QUICK", "0") not in ("", "0", "false", "False")
N = 1_000 if QUICK else 10_000
CHUNK = N // 4

# %% [markdown]
# ## The members
#
# A box of sides (1, 2, 3) and unit mass. The spin directions are a Fibonacci lattice on
# the sphere (nearly uniform), all at `|ω| = 1 rad/s`; each member is simulated for 20
# rotation periods and sampled ten times a period. The states are built for all members
# at once with `jax.vmap`.

# %%
moments = inertia.box(1.0, 1.0, 2.0, 3.0)
scene = jrigid.Scene(jrigid.RigidBody(moments))
directions = stability.fibonacci_sphere(N)
states = jax.vmap(lambda w: initial.from_omega(None, w))(directions)
periods = 20
ts = jnp.linspace(0.0, periods * 2 * math.pi, 10 * periods + 1)
print("moments:", np.asarray(moments), " states:", states.q.shape, states.qdot.shape)

# %% [markdown]
# `simulate_many` keeps, per member, whatever a `summary` function returns; the default
# is `q` and `ω` at every sample, 10⁴ × 201 × 7 numbers. Reduce inside the compiled
# program instead: `stability.trajectory_summary` finds the principal axis nearest to
# `ω(0)`, the largest angle it turns away from its start, and the number of flips (sign
# changes of its body `ω` component, which are its crossings of the plane normal to `L`).


# %%
def summary(traj):
    out = stability.trajectory_summary(traj.ts, traj.q, traj.omega)
    out["result"] = traj.result
    out["num_steps"] = traj.stats["num_steps"]
    return out


# %% [markdown]
# ## A run on disk, interrupted and resumed
#
# With `out_dir`, every finished chunk is written atomically (`chunk_00000.npz`, …) next
# to `meta.json`, which records the member count, the chunking, a fingerprint of the
# inputs and settings, and your `metadata`. Members are ordered by a closed-form proxy of
# their cost (`|L|²`, `stability.difficulty_order`) so that a chunk's members need similar
# numbers of steps: under `vmap` a chunk runs until its slowest member is done.

# %%
out_dir = Path(tempfile.mkdtemp()) / "box_map"
proxy = jnp.sum((moments * directions) ** 2, axis=-1)
order = stability.difficulty_order(proxy)
settings = dict(summary=summary, chunk_size=CHUNK, out_dir=out_dir, order=order,
                metadata={"sides": [1, 2, 3], "periods": periods}, progress=False)
info = {}
t0 = time.perf_counter()
first = ensemble.simulate_many(scene, states, ts, info=info, **settings)
print(f"{N} members in {time.perf_counter() - t0:.1f} s: compile {info['compile_seconds']:.1f} s, "
      f"run {info['run_seconds']:.1f} s, {info['chunks_computed']} chunks computed")
print(sorted(p.name for p in out_dir.iterdir()))

# %% [markdown]
# A run killed after two of its four chunks (Ctrl-C, a lost node, `kill -9`) leaves what
# it had written: `meta.json` and the finished chunks. We reproduce that state by
# deleting the last two chunk files, then call *the same function again*: the finished
# chunks are loaded and only the missing ones computed. (The compiled program is reused:
# same `summary` object, same shapes.)

# %%
for path in sorted(out_dir.glob("chunk_*.npz"))[2:]:
    path.unlink()
print("left on disk:", sorted(p.name for p in out_dir.iterdir()))
info = {}
t0 = time.perf_counter()
resumed = ensemble.simulate_many(scene, states, ts, info=info, **settings)
print(f"resumed in {time.perf_counter() - t0:.1f} s: {info['chunks_loaded']} chunks loaded, "
      f"{info['chunks_computed']} computed")
print("identical to the uninterrupted run:", all(np.array_equal(first[k], resumed[k]) for k in first))

# %% [markdown]
# A different call on the same folder (other inputs, other settings) is refused with a
# `ValueError` rather than mixed with the stored chunks:

# %%
try:
    ensemble.simulate_many(scene, states, ts[:-1], **settings)
except ValueError as error:
    print("ValueError:", str(error)[:300])

# %% [markdown]
# ## The map
#
# Every member succeeded, and a member flips exactly when the closed form says its
# nearest axis is not the one its polhode encircles (`stability.flips_expected`):

# %%
out = resumed
flips = out["flips"] > 0
expected = np.asarray(jax.vmap(stability.flips_expected, in_axes=(None, 0))(moments, directions))
print("all succeeded:", bool(np.all(out["result"] == 0)))
print(f"flipping directions: {100 * flips.mean():.1f} % (closed form {100 * expected.mean():.1f} %), "
      f"agreement {100 * np.mean(flips == expected):.2f} %")
print("steps per member: min", out["num_steps"].min(), " median", int(np.median(out["num_steps"])),
      " max", out["num_steps"].max())

# %% [markdown]
# Drawn on the globe and on a Mollweide map of body-frame directions (white: polhodes,
# the curves body `ω` follows, and the separatrix through the middle axis). Near the
# largest and smallest axes the nearest axis barely moves; inside the band around the
# middle axis it turns over, the sooner the closer the spin is to the separatrix.

# %%
first_flip = np.where(np.isfinite(out["first_flip"]), out["first_flip"], np.nan)
fig = stability_views.stability_figure(
    np.asarray(directions),
    {
        "largest angle of the nearest axis (degrees)": np.degrees(out["max_axis_angle"]),
        "time of the first flip (s)": first_flip,
    },
    np.asarray(moments),
    polhodes=stability.polhode_family(moments, levels=7),
    width=13,
    title=f"box (1, 2, 3), |ω| = 1 rad/s, {periods} periods, {N} directions",
)
fig

# %% [markdown]
# ## Scaling out
#
# The same call runs unchanged on more hardware; what changes is only where the members
# go. (In more detail: [Scaling out](../../scaling_out/).)
#
# - **Several devices on one machine.** `devices=None` (the default) splits every chunk
#   over all of `jax.devices()`: all GPUs of the host, or `K` CPU devices with
#   `XLA_FLAGS=--xla_force_host_platform_device_count=K` set before JAX is imported.
#   With `shared_step=False` the results are bit-identical to one device; with the
#   default shared step (below) each device's share is one group, so the groups, and the
#   results to within the tolerance (6e-11 at the default rtol with 2 devices), depend
#   on the device count.
# - **A shared step for throughput (the default).** `simulate_many` integrates each
#   device's share of a chunk as one system with one adaptive step
#   (`ensemble.simulate_lockstep`): on a CPU, where per-member step control costs more
#   than a rigid body's vector field, several times the throughput (see the
#   [benchmarks](../../benchmarks/#throughput-of-a-stability-map)), at the price that a
#   member's result depends (within tolerance) on its group. `shared_step=False` gives
#   every member its own step control.
# - **Several hosts, one mesh.** Start the same script on every host, call
#   `jax.distributed.initialize()` first, and make the same `simulate_many` call with the
#   same inputs: `jax.devices()` is then global, each chunk is split over every device of
#   every host, and process 0 writes `out_dir` (on a shared file system).
# - **Independent slices.** Without coordination: host `i` of `P` takes `states[i::P]`
#   with `devices=jax.local_devices()` and its own `out_dir`; concatenate afterwards. A
#   failed host loses nothing else and resumes on its own.
#
# Chunk size bounds memory (each chunk's outputs are held at once) and sets how much is
# lost to an interruption; a few thousand members per chunk keeps a CPU busy.
