"""Tests of jrigid.ensemble: chunking, padding, storage, resume, sharding, simulate_many.

Reference results are one straight ``jax.jit(jax.vmap(fn))`` over all members (what a
chunked run must reproduce bit for bit) and, for the physics, scipy ``solve_ivp``.
The sharded run executes in a subprocess with four forced host CPU devices
(``XLA_FLAGS`` must be set before JAX is imported) and is compared bit for bit with the
in-process single-device run.
"""

from __future__ import annotations

import json
import os
import signal
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _ensemble import python as _python

from jrigid import RigidBody, Scene, ensemble, initial

MOMENTS = (1.0, 2.0, 3.0)


def rotor(member):
    """Euler's equations, RK4 with a per-member step count (a data-dependent loop)."""
    inertia = jnp.asarray(MOMENTS, dtype=member["omega"].dtype)

    def field(w):
        return jnp.stack(
            [
                (inertia[1] - inertia[2]) * w[1] * w[2] / inertia[0],
                (inertia[2] - inertia[0]) * w[2] * w[0] / inertia[1],
                (inertia[0] - inertia[1]) * w[0] * w[1] / inertia[2],
            ]
        )

    h = member["t1"] / member["steps"]

    def step(state):
        i, w = state
        k1 = field(w)
        k2 = field(w + 0.5 * h * k1)
        k3 = field(w + 0.5 * h * k2)
        k4 = field(w + h * k3)
        return i + 1, w + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    _, w = jax.lax.while_loop(lambda s: s[0] < member["steps"], step, (0, member["omega"]))
    energy = 0.5 * jnp.sum(inertia * w * w)
    return {"omega": w, "energy": energy, "tag": member["tag"]}


def rotor_inputs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "omega": rng.normal(size=(n, 3)),
        "t1": rng.uniform(0.5, 2.0, size=n),
        "steps": rng.integers(20, 200, size=n).astype(np.int32),
        "tag": np.arange(n, dtype=np.int32),
    }


def straight(fn, inputs):
    """One ``jax.jit(jax.vmap(fn))`` call over all members (the reference)."""
    return jax.tree_util.tree_map(np.asarray, jax.jit(jax.vmap(fn))(inputs))


def assert_identical(a: dict, b: dict):
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        np.testing.assert_array_equal(a[k], b[k], err_msg=k, strict=True)


def counting(fn):
    """``fn`` plus a host callback counting the members it is evaluated on."""
    calls = []

    def counted(member):
        jax.debug.callback(lambda tag: calls.append(int(tag)), member["tag"])
        return fn(member)

    return counted, calls


@pytest.mark.parametrize("chunk_size", [1, 3, 7, 64])
def test_chunked_equals_straight_vmap_bit_for_bit(chunk_size):
    inputs = rotor_inputs(10)
    info: dict = {}
    out = ensemble.run(rotor, inputs, chunk_size=chunk_size, progress=False, info=info)
    assert_identical(out, straight(rotor, inputs))
    size = min(chunk_size, 10)
    assert info["chunk_size"] == size and info["n_chunks"] == -(-10 // size)


def _euler_rhs(t, w):
    i1, i2, i3 = MOMENTS
    return [
        (i2 - i3) * w[1] * w[2] / i1,
        (i3 - i1) * w[2] * w[0] / i2,
        (i1 - i2) * w[0] * w[1] / i3,
    ]


def test_rk4_rotor_is_right():
    """The test function itself against scipy: final ω to RK4 accuracy (error ∝ h⁴)."""
    from scipy.integrate import solve_ivp

    inputs = rotor_inputs(3, seed=1)
    out = ensemble.run(rotor, inputs, chunk_size=2, progress=False)
    for i in range(3):
        w0, t1 = inputs["omega"][i], inputs["t1"][i]
        ref = solve_ivp(_euler_rhs, (0, t1), w0, method="DOP853", rtol=1e-13, atol=1e-13)
        h = t1 / inputs["steps"][i]
        err = np.abs(out["omega"][i] - ref.y[:, -1]).max()
        assert err < 10 * t1 * (h * np.abs(w0).max()) ** 4 * np.abs(w0).max()


def test_padding_and_trim():
    """N not a multiple of chunk_size: the last chunk is padded, results trimmed, in order."""
    inputs = rotor_inputs(10)
    counted, calls = counting(rotor)
    info: dict = {}
    out = ensemble.run(counted, inputs, chunk_size=4, progress=False, info=info)
    assert out["tag"].tolist() == list(range(10))
    assert out["omega"].shape == (10, 3) and out["energy"].shape == (10,)
    # chunks [0-3], [4-7], [8, 9, 9, 9]: padding repeats the chunk's last member
    assert sorted(calls) == [*range(9), 9, 9, 9]
    assert info["batch"] == 4 and info["chunks_computed"] == 3
    assert_identical(out, straight(rotor, inputs))


def test_order_groups_members_and_restores_input_order(tmp_path):
    """With ``order`` the chunks hold the permuted members; results come back in input order."""
    inputs = rotor_inputs(10)
    order = np.argsort(inputs["steps"])  # group members of similar cost
    counted, calls = counting(rotor)
    out = ensemble.run(counted, inputs, chunk_size=4, progress=False, order=order,
                       out_dir=tmp_path)
    # chunks order[0:4], order[4:8], order[8:10] padded with order[9]
    assert sorted(calls) == sorted([*range(10), order[9], order[9]])
    assert_identical(out, straight(rotor, inputs))
    stored = np.load(tmp_path / "chunk_00000.npz")["tag"]
    assert stored.tolist() == order[:4].tolist()  # the first chunk holds the cheapest members
    with pytest.raises(ValueError, match="differ|match|another"):  # order is fingerprinted
        ensemble.run(rotor, inputs, chunk_size=4, progress=False, out_dir=tmp_path)
    for bad in (order[:-1], np.zeros(10, dtype=int), order.astype(float)):
        with pytest.raises(ValueError, match="permutation"):
            ensemble.run(rotor, inputs, chunk_size=4, progress=False, order=bad)


def test_one_member_and_chunk_larger_than_n():
    inputs = rotor_inputs(1)
    out = ensemble.run(rotor, inputs, chunk_size=1000, progress=False)
    assert_identical(out, straight(rotor, inputs))


def scaled_rotor(member, shared):
    out = rotor(member)
    return {"omega": shared["scale"] * out["omega"], "tag": out["tag"]}


def test_shared_values_are_traced_and_fingerprinted(tmp_path):
    inputs = rotor_inputs(6)
    base = straight(rotor, inputs)["omega"]
    info: dict = {}
    for scale in (2.0, 3.0):
        out = ensemble.run(scaled_rotor, inputs, shared={"scale": np.float64(scale)},
                           chunk_size=4, progress=False, info=info)
        np.testing.assert_array_equal(out["omega"], scale * base)
    assert info["compile_seconds"] == 0.0  # the second value reused the compiled program
    ensemble.run(scaled_rotor, inputs, shared={"scale": np.float64(2.0)}, chunk_size=4,
                 out_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match="different run.*shared inputs' values"):
        ensemble.run(scaled_rotor, inputs, shared={"scale": np.float64(3.0)}, chunk_size=4,
                     out_dir=tmp_path, progress=False)
    # a shared input of another shape is named, with its shapes ("differs in: shared")
    with pytest.raises(ValueError, match=r"shared inputs: \['scale'\] \(shape \[\] dtype <f8 "
                                         r"→ shape \[3\]"):
        ensemble.run(scaled_rotor, inputs, shared={"scale": np.full(3, 2.0)}, chunk_size=4,
                     out_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match=r"shared\['scale'\] has non-finite"):
        ensemble.run(scaled_rotor, inputs, shared={"scale": np.float64(np.inf)})


def test_files_and_meta(tmp_path):
    inputs = rotor_inputs(10)
    out = ensemble.run(
        rotor, inputs, chunk_size=4, out_dir=tmp_path, metadata={"seed": 0}, progress=False
    )
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [".lock", "chunk_00000.npz", "chunk_00001.npz", "chunk_00002.npz",
                     "meta.json"]
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["n_members"] == 10 and meta["chunk_size"] == 4 and meta["n_chunks"] == 3
    assert meta["metadata"] == {"seed": 0}
    assert meta["outputs"]["omega"] == {"shape": [3], "dtype": "<f8"}
    assert meta["outputs"]["tag"] == {"shape": [], "dtype": "<i4"}
    assert meta["versions"]["jax"] == jax.__version__ and "diffrax" in meta["versions"]
    assert len(meta["inputs"]["sha256"]) == 64 and "completed" in meta
    with np.load(tmp_path / "chunk_00002.npz") as last:
        assert last["tag"].tolist() == [8, 9]
        np.testing.assert_array_equal(last["omega"], out["omega"][8:])


def test_resume_recomputes_only_missing_chunks(tmp_path):
    inputs = rotor_inputs(10)
    first = ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False)
    kept = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("chunk_*.npz")}
    (tmp_path / "chunk_00001.npz").unlink()
    del kept["chunk_00001.npz"]
    time.sleep(0.01)
    counted, calls = counting(rotor)
    info: dict = {}
    again = ensemble.run(counted, inputs, chunk_size=4, out_dir=tmp_path, progress=False, info=info)
    assert sorted(calls) == [4, 5, 6, 7]
    assert info["chunks_loaded"] == 2 and info["chunks_computed"] == 1
    assert {p: (tmp_path / p).stat().st_mtime_ns for p in kept} == kept
    assert (tmp_path / "chunk_00001.npz").exists()
    assert_identical(again, first)
    calls.clear()
    third = ensemble.run(counted, inputs, chunk_size=4, out_dir=tmp_path, progress=False)
    assert calls == []
    assert_identical(third, first)


def test_unreadable_chunk_is_recomputed(tmp_path):
    inputs = rotor_inputs(6)
    first = ensemble.run(rotor, inputs, chunk_size=3, out_dir=tmp_path, progress=False)
    (tmp_path / "chunk_00000.npz").write_bytes(b"not a zip file")
    counted, calls = counting(rotor)
    again = ensemble.run(counted, inputs, chunk_size=3, out_dir=tmp_path, progress=False)
    assert sorted(calls) == [0, 1, 2]
    assert_identical(again, first)


@pytest.mark.parametrize(
    "change, field",
    [
        (dict(inputs=rotor_inputs(10, seed=5)), "inputs"),
        (dict(chunk_size=5), "chunk_size"),
        (dict(metadata={"seed": 1}), "metadata"),
        (dict(fn=lambda m: {"energy": rotor(m)["energy"]}), "outputs"),
    ],
)
def test_mismatched_run_raises(tmp_path, change, field):
    base = dict(fn=rotor, inputs=rotor_inputs(10), chunk_size=4, metadata={"seed": 0})
    ensemble.run(base["fn"], base["inputs"], chunk_size=4, out_dir=tmp_path,
                 metadata=base["metadata"], progress=False)
    args = {**base, **change}
    with pytest.raises(ValueError, match=f"different run.*{field}.*another out_dir"):
        ensemble.run(args["fn"], args["inputs"], chunk_size=args["chunk_size"],
                     out_dir=tmp_path, metadata=args["metadata"], progress=False)
    # resume=False discards the stored run and starts over
    counted, calls = counting(args["fn"])
    out = ensemble.run(counted, args["inputs"], chunk_size=args["chunk_size"], out_dir=tmp_path,
                       metadata=args["metadata"], progress=False, resume=False)
    assert sorted(set(calls)) == list(range(10))
    assert_identical(out, straight(args["fn"], args["inputs"]))
    assert json.loads((tmp_path / "meta.json").read_text())["chunk_size"] == args["chunk_size"]


@pytest.mark.parametrize("text", ["{not json", json.dumps([1, 2]), json.dumps({"a": 1})])
def test_corrupted_meta_raises(tmp_path, text):
    ensemble.run(rotor, rotor_inputs(4), chunk_size=2, out_dir=tmp_path, progress=False)
    (tmp_path / "meta.json").write_text(text)
    with pytest.raises(ValueError, match="meta.json.*(unreadable|not the meta).*another out_dir"):
        ensemble.run(rotor, rotor_inputs(4), chunk_size=2, out_dir=tmp_path, progress=False)


def test_chunks_without_meta_raise(tmp_path):
    ensemble.run(rotor, rotor_inputs(4), chunk_size=2, out_dir=tmp_path, progress=False)
    (tmp_path / "meta.json").unlink()
    with pytest.raises(ValueError, match="chunk files but no meta.json.*resume=False"):
        ensemble.run(rotor, rotor_inputs(4), chunk_size=2, out_dir=tmp_path, progress=False)


def test_bad_inputs_raise(tmp_path):
    good = rotor_inputs(4)
    with pytest.raises(ValueError, match="share the leading.*'t1'"):
        ensemble.run(rotor, {**good, "t1": np.ones(3)})
    with pytest.raises(ValueError, match=r"inputs\['t1'\] is a scalar"):
        ensemble.run(rotor, {**good, "t1": 1.0})
    bad = {**good, "omega": good["omega"].copy()}
    bad["omega"][2, 1] = np.nan
    with pytest.raises(ValueError, match=r"inputs\['omega'\] has non-finite.*member 2"):
        ensemble.run(rotor, bad)
    with pytest.raises(ValueError, match="no members"):
        ensemble.run(rotor, {k: v[:0] for k, v in good.items()})
    with pytest.raises(ValueError, match="no arrays"):
        ensemble.run(rotor, {})
    with pytest.raises(ValueError, match="chunk_size must be a positive int"):
        ensemble.run(rotor, good, chunk_size=0)
    with pytest.raises(ValueError, match="metadata must be JSON"):
        ensemble.run(rotor, good, metadata={"f": object()})
    with pytest.raises(ValueError, match="must return a non-empty dict"):
        ensemble.run(lambda m: m["omega"], good)
    with pytest.raises(ValueError, match="output 'x' must be one array"):
        ensemble.run(lambda m: {"x": (m["omega"], m["t1"])}, good)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="not a folder"):
        ensemble.run(rotor, good, out_dir=tmp_path / "file")


def test_float32(float32):
    inputs = {k: (v.astype(np.float32) if v.dtype == np.float64 else v)
              for k, v in rotor_inputs(7).items()}
    out = ensemble.run(rotor, inputs, chunk_size=3, progress=False)
    assert out["omega"].dtype == np.float32
    assert_identical(out, straight(rotor, inputs))


def test_sharded_over_four_devices_equals_single_device(tmp_path):
    code = f"""
    from jrigid.ensemble import sharding
    assert len(jax.devices()) == 4, jax.devices()
    placed = sharding.place([np.arange(8.0)], sharding.member_sharding(jax.devices()))[0]
    assert len({{s.device for s in placed.addressable_shards}}) == 4
    info = {{}}
    out = ensemble.run(rotor, rotor_inputs(23), chunk_size=10, progress=False, info=info,
                       out_dir={str(tmp_path / "run")!r})
    assert info["n_devices"] == 4 and info["batch"] == 12, info
    np.savez({str(tmp_path / "sharded.npz")!r}, **out)
    """
    proc = _python(code, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    with np.load(tmp_path / "sharded.npz") as data:
        sharded = {k: data[k] for k in data.files}
    inputs = rotor_inputs(23)
    single = ensemble.run(rotor, inputs, chunk_size=10, progress=False)
    assert_identical(sharded, single)
    assert_identical(sharded, straight(rotor, inputs))
    # a run written with 4 devices resumes on 1 (the chunking does not depend on devices)
    info: dict = {}
    resumed = ensemble.run(rotor, inputs, chunk_size=10, out_dir=tmp_path / "run",
                           progress=False, info=info)
    assert info["chunks_loaded"] == 3 and info["chunks_computed"] == 0
    assert_identical(resumed, single)


def test_killed_run_resumes_without_loss(tmp_path):
    """Kill a run (SIGKILL) after its first chunks are written; resume computes the rest."""
    out_dir = tmp_path / "run"
    code = f"""
    def slow(member):
        jax.debug.callback(lambda: time.sleep(0.15))
        return rotor(member)
    ensemble.run(slow, rotor_inputs(40), chunk_size=4, out_dir={str(out_dir)!r},
                 progress=False)
    """
    proc = _python(code)
    try:
        deadline = time.monotonic() + 60
        # chunks run on several threads and may finish out of order: wait for any two
        while len(list(out_dir.glob("chunk_*.npz"))) < 2:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no chunk written within 60 s"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    finished = sorted(p.name for p in out_dir.glob("chunk_*.npz"))
    assert 2 <= len(finished) < 10, finished
    mtimes = {p: (out_dir / p).stat().st_mtime_ns for p in finished}
    counted, calls = counting(rotor)
    info: dict = {}
    inputs = rotor_inputs(40)
    out = ensemble.run(counted, inputs, chunk_size=4, out_dir=out_dir, progress=False, info=info)
    done = {int(p[6:11]) for p in finished}
    assert info["chunks_loaded"] == len(done) and info["chunks_computed"] == 10 - len(done)
    assert sorted(calls) == [i for i in range(40) if i // 4 not in done]
    assert {p: (out_dir / p).stat().st_mtime_ns for p in finished} == mtimes
    assert not list(out_dir.glob(".*.tmp"))
    assert_identical(out, straight(rotor, inputs))


def test_simulate_many_against_scipy(tmp_path):
    """simulate_many (Tsit5) against scipy DOP853 on Euler's equations + q̇ = ½ q ⊗ (0, ω)."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(3)
    omegas = rng.normal(size=(5, 3))
    q0 = rng.normal(size=(5, 4))
    q0 /= np.linalg.norm(q0, axis=1, keepdims=True)
    states = jax.vmap(initial.from_omega)(jnp.asarray(q0), jnp.asarray(omegas))
    scene = Scene(RigidBody(jnp.asarray(MOMENTS)))
    ts = np.linspace(0.0, 5.0, 4)
    out = ensemble.simulate_many(
        scene, states, ts, chunk_size=2, out_dir=tmp_path, rtol=1e-10, atol=1e-12,
        summary=lambda tr: {"q": tr.q[-1], "omega": tr.omega[-1], "result": tr.result},
        progress=False,
    )
    i1, i2, i3 = MOMENTS

    def rhs(t, y):
        w0, w1, w2 = y[4:]
        a, b, c, d = y[:4]
        return [
            0.5 * (-b * w0 - c * w1 - d * w2), 0.5 * (a * w0 + c * w2 - d * w1),
            0.5 * (a * w1 - b * w2 + d * w0), 0.5 * (a * w2 + b * w1 - c * w0),
            (i2 - i3) * w1 * w2 / i1, (i3 - i1) * w2 * w0 / i2, (i1 - i2) * w0 * w1 / i3,
        ]

    assert out["result"].tolist() == [0] * 5
    for k in range(5):
        y = solve_ivp(rhs, (0, 5.0), np.r_[q0[k], omegas[k]], method="DOP853",
                      rtol=1e-13, atol=1e-13).y[:, -1]
        np.testing.assert_allclose(out["omega"][k], y[4:], atol=1e-7)
        sign = np.sign(np.dot(out["q"][k], y[:4]))
        np.testing.assert_allclose(sign * out["q"][k], y[:4], atol=1e-7)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["shared"]["leaves"]["['ts']"]["shape"] == [4]
    assert "rtol" not in meta["metadata"]["simulate"]["kwargs"]  # traced: in "shared"
