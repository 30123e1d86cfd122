"""Stability map of a box: spun near its largest or smallest axis it stays; near the middle, flips.

For every direction ``d`` of a Fibonacci lattice on the sphere (10⁴ directions; 300 in
quick mode) the box (sides ``a, b, c``, :func:`jrigid.inertia.box`) is spun torque free
with ``ω(0) = |ω| d`` (or, with ``mode="energy"``, at a fixed kinetic energy), simulated
with :func:`jrigid.simulate` (its default solver, ``rtol`` 1e-8) over 50 rotation periods
``2π/|ω|``, and three numbers are kept (:func:`jrigid.stability.map_member`):

* the largest angle the principal axis nearest to ``ω(0)`` moves from its initial
  direction in space;
* the number of flips of that axis (sign changes of its body component of ω, which are
  the sign changes of its projection on the conserved ``L``), and the first flip time;
* the finite-time Lyapunov exponent of Euler's equations over one rotation period, by
  ``jax.jacfwd`` through the closed-form motion (:func:`jrigid.stability.ftle_exact`).

A direction counts as *unstable* if its nearest axis flips at least once. The closed form
predicts which directions must flip (the nearest axis is not the one the polhode
encircles, :func:`jrigid.stability.flips_expected`): the map is checked against it, and the
FTLE is summarised in caps of 15° about each axis. The members run through
:func:`jrigid.ensemble.run` in chunks written under ``out_dir/chunks/<settings>`` (an
interrupted map resumes; other parameters start their own folder), ordered by a
closed-form difficulty proxy, ``|L|²`` (see ``benchmarks/lockstep.py``), so that
members of a chunk need similar step counts.

Run it with ``jrigid run stability_map [--quick]`` or ``python experiments/stability_map.py``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import jax
import jax.numpy as jnp
import numpy as np

from jrigid import ensemble, inertia, stability
from jrigid.ensemble import storage
from jrigid.experiment_parameters import POSITIVE
from jrigid.report import Report
from jrigid.viz import stability as vs

CAP_DEG = 15.0


def _cap_stats(values, mask) -> dict:
    v = np.asarray(values, float)[mask]
    return dict(
        count=int(v.size),
        mean=float(v.mean()),
        median=float(np.median(v)),
        min=float(v.min()),
        max=float(v.max()),
    )


def _sweep(member, omega0, order, chunk_size, out_dir, info, executor, metadata) -> dict:
    """The map's ensemble run (in this process, or on ``executor``)."""
    return ensemble.run(
        member,
        {"omega0": np.asarray(omega0)},
        order=order,
        chunk_size=chunk_size,
        out_dir=out_dir,
        metadata=metadata,
        info=info,
        executor=executor,
    )


def main(
    out_dir,
    quick: bool = False,
    *,
    sides: Annotated[tuple, POSITIVE] = (1.0, 2.0, 3.0),
    n_directions: Annotated[int, POSITIVE] = 10_000,
    mode: str = "speed",
    periods: Annotated[float, POSITIVE] = 50.0,
    samples_per_period: Annotated[int, POSITIVE] = 10,
    ftle_periods: Annotated[float, POSITIVE] = 1.0,
    rtol: Annotated[float, POSITIVE] = 1e-8,
    chunk_size: Annotated[int, POSITIVE] = 1024,
    sort: bool = True,
    workers: int = 0,
    scheduler: str = "",
) -> dict:
    """Map principal-axis stability over the sphere of spin directions.

    Args:
        out_dir: results folder (chunks in ``out_dir/chunks/<settings>``: one folder per
            set of parameters, so a run with other parameters starts its own sweep).
        quick: 300 directions, 20 periods, chunks of 100.
        sides: box side lengths ``a, b, c`` (unit mass).
        n_directions: Fibonacci directions (at least 200).
        mode: ``"speed"`` (``|ω| = 1``) or ``"energy"`` (``2E = I_mid``, so ``|ω| = 1``
            along the middle axis).
        periods: simulated time in rotation periods ``2π``.
        samples_per_period: output samples per period (flips and angles are read there).
        ftle_periods: FTLE horizon in rotation periods.
        rtol: relative tolerance (``atol = rtol/100``).
        chunk_size: members per ensemble chunk.
        sort: order members by the difficulty proxy ``|L|²`` before chunking.
        workers: compute the chunks on a local Dask cluster of this many worker
            processes (``jrigid run stability_map --workers N``); 0: in this process.
        scheduler: compute them on the Dask scheduler at this address instead
            (``--scheduler tcp://head:8786``; a dask-jobqueue cluster's, for Slurm).
            Results are the same bit for bit either way.

    Returns:
        the numbers written to ``numbers.json``.
    """
    if mode not in ("speed", "energy"):
        raise ValueError(f"mode must be 'speed' or 'energy', got {mode!r}")
    if n_directions < 200 and not quick:  # a 15° cap holds 1.7 % of the sphere
        raise ValueError(f"n_directions must be >= 200, so that each 15° cap about an axis "
                         f"holds directions; got {n_directions}")
    if quick:
        n_directions, periods, chunk_size = 300, min(periods, 20.0), 100
    moments = jnp.asarray(inertia.box(1.0, *sides))
    mom = np.asarray(moments)
    lo, mid, hi = (int(k) for k in np.argsort(mom))
    dirs = stability.fibonacci_sphere(n_directions)
    if mode == "speed":
        omega0 = dirs
    else:
        omega0 = stability.omega_at_energy(
            dirs, jnp.broadcast_to(moments, dirs.shape), jnp.full(dirs.shape[:1], 0.5 * mom[mid])
        )
    period = 2.0 * math.pi
    t_end = periods * period
    ts = jnp.linspace(0.0, t_end, int(round(periods * samples_per_period)) + 1)
    ftle_time = ftle_periods * period

    def member(x):
        return stability.map_member(moments, x["omega0"], ts, ftle_time, rtol=rtol, atol=rtol / 100)

    proxy = jnp.sum((moments[None, :] * omega0) ** 2, axis=-1)  # |L|², see benchmarks/lockstep.py
    order = np.asarray(stability.difficulty_order(proxy)) if sort else np.arange(n_directions)
    info: dict = {}
    settings = dict(sides=list(sides), mode=mode, periods=periods, rtol=rtol,
                    samples_per_period=samples_per_period, ftle_periods=ftle_periods,
                    sort=sort)
    chunks = storage.folder_for(Path(out_dir) / "chunks",
                                dict(settings, n_directions=n_directions, chunk_size=chunk_size))
    with ensemble.executor(workers=workers, scheduler=scheduler) as pool:
        out = _sweep(member, omega0, order, chunk_size, chunks, info, pool, settings)

    ok = out["result"] == 0
    if not ok.any():
        codes = sorted({int(c) for c in np.unique(out["result"])})
        raise RuntimeError(f"stability_map: every one of the {n_directions} solves failed "
                           f"(result codes {codes}, jrigid.Result): no map to draw")
    steps = np.asarray(out["num_steps"])  # every member's, for the lockstep efficiency
    # a failed member (flips -1, NaN angles) is left out of every statistic, and counted
    d, out = np.asarray(dirs)[ok], {k: np.asarray(v)[ok] for k, v in out.items()}
    unstable = out["flips"] > 0
    caps = {
        name: np.abs(d[:, k]) > math.cos(math.radians(CAP_DEG))
        for name, k in (("smallest", lo), ("intermediate", mid), ("largest", hi))
    }
    numbers = {
        "moments": mom,
        "axes_smallest_intermediate_largest": [lo + 1, mid + 1, hi + 1],
        "n_directions": n_directions,
        "mode": mode,
        "periods": periods,
        "all_succeeded": bool(ok.all()),
        "failed_members": int((~ok).sum()),
        "fraction_unstable": float(unstable.mean()),
        "fraction_unstable_closed_form": float(out["flips_expected"].mean()),
        "classification_agreement": float(np.mean(unstable == out["flips_expected"])),
        "cap_deg": CAP_DEG,
        "cap_fraction_unstable": {n: float(unstable[m].mean()) for n, m in caps.items()},
        "cap_max_axis_angle_deg": {
            n: float(np.degrees(out["max_axis_angle"][m].max())) for n, m in caps.items()
        },
        "cap_ftle": {n: _cap_stats(out["ftle"], m) for n, m in caps.items()},
        "ftle_time": ftle_time,
        "saddle_rate_lambda": float(
            math.sqrt((mom[hi] - mom[mid]) * (mom[mid] - mom[lo]) / (mom[lo] * mom[hi]))
        ),
        "ftle_median_unstable": float(np.median(out["ftle"][unstable])),
        "ftle_median_stable": float(np.median(out["ftle"][~unstable])),
        "first_flip_median": float(np.median(out["first_flip"][unstable])),
        "steps_min_median_max": [int(out["num_steps"].min()), int(np.median(out["num_steps"])),
                                 int(out["num_steps"].max())],
        "lockstep_efficiency_this_run": float(
            stability.lockstep_efficiency(steps, chunk_size, order)
        ),
        "lockstep_efficiency_unsorted": float(stability.lockstep_efficiency(steps, chunk_size)),
        "compile_seconds": info.get("compile_seconds"),
        "run_seconds": info.get("run_seconds"),
        "chunks_loaded": info.get("chunks_loaded"),
    }

    rep = Report(Path(out_dir), title="Principal-axis stability map")
    rep.text(
        f"A box of sides {list(sides)} (moments {np.round(mom, 4).tolist()}; smallest axis "
        f"{lo + 1}, intermediate {mid + 1}, largest {hi + 1}) spun along {n_directions} "
        f"directions ({mode} fixed), {periods:g} rotation periods, jrigid's default solver "
        f"at rtol {rtol:g}. "
        f"{100 * numbers['fraction_unstable']:.1f}% of the directions flip their nearest axis "
        f"(closed form: {100 * numbers['fraction_unstable_closed_form']:.1f}%; agreement "
        f"{100 * numbers['classification_agreement']:.2f}%). Within {CAP_DEG:g}° of the "
        "smallest / intermediate / largest axis the unstable fraction is "
        + " / ".join(f"{numbers['cap_fraction_unstable'][n]:.2f}" for n in caps)
        + ", the median FTLE "
        + " / ".join(f"{numbers['cap_ftle'][n]['median']:.3f}" for n in caps)
        + f" (saddle rate λ = {numbers['saddle_rate_lambda']:.3f})."
    )
    if not ok.all():
        rep.text(f"**{numbers['failed_members']} of the {n_directions} solves failed** "
                 "(their result codes are in the chunks) and are left out of every number "
                 "and of the map.")
    rep.table(
        [
            (
                n,
                numbers["cap_fraction_unstable"][n],
                numbers["cap_max_axis_angle_deg"][n],
                numbers["cap_ftle"][n]["median"],
                numbers["cap_ftle"][n]["max"],
            )
            for n in caps
        ],
        headers=("axis cap", "fraction unstable", "max axis angle (°)", "FTLE median", "FTLE max"),
        digits=4,
    )
    polh = stability.polhode_family(moments, levels=5 if quick else 7)
    first = np.where(np.isfinite(out["first_flip"]), out["first_flip"], np.nan)
    fields = {
        "max axis angle (°)": np.degrees(out["max_axis_angle"]),
        "flips (capped at 20)": np.minimum(out["flips"], 20),
        "first flip time (blank: none)": first,
        f"FTLE over {ftle_periods:g} period": out["ftle"],
    }
    title = f"box {list(sides)}: principal-axis stability ({n_directions} directions)"
    style = dict(
        cmaps={"flips (capped at 20)": "magma", "first flip time (blank: none)": "plasma"},
        limits={"max axis angle (°)": (0, 180), "flips (capped at 20)": (0, 20)},
    )
    fig = vs.stability_figure(d, fields, mom, polhodes=polh, title=title, **style)
    rep.figure(
        "map",
        fig,
        caption="globe (left) and equal-area Mollweide map (right) of the "
        "spin directions; white: polhodes and the separatrix",
        dpi=70 if quick else 100,
    )
    if not quick:  # a compact version (two quantities) for galleries
        keep = ("max axis angle (°)", f"FTLE over {ftle_periods:g} period")
        fig = vs.stability_figure(
            d, {k: fields[k] for k in keep}, mom, polhodes=polh, title=title, **style
        )
        rep.figure("map_angle_ftle", fig, caption="the same, two quantities", show=False)
    rep.numbers(numbers)
    rep.write_summary()
    failed = f", {numbers['failed_members']} solves failed" if not ok.all() else ""
    print(
        f"stability_map: {100 * numbers['fraction_unstable']:.1f}% unstable, agreement "
        f"{numbers['classification_agreement']:.4f}{failed}"
    )
    return numbers


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    main(Path("results") / "stability_map")
