"""jrigid.ensemble on real executors: a Dask ``LocalCluster`` of two worker processes, a
standard-library ``ProcessPoolExecutor``, and the ``jax.distributed`` route with two
processes.

Every run is compared bit for bit with one straight ``jax.jit(jax.vmap(fn))`` in this
process (and ``simulate_many`` with its own in-process run): a worker computes the same
program on the same numbers, so nothing may differ. Failures are real: a worker process
killed with SIGKILL in the middle of a sweep, a driver process killed with SIGKILL, two
drivers on one folder.
"""

from __future__ import annotations

import os
import pathlib
import signal
import socket
import subprocess
import sys
import threading
import time

import cloudpickle
import distributed
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import test_ensemble
from test_ensemble import assert_identical, rotor, rotor_inputs, straight

from jrigid import RigidBody, Scene, ensemble, initial
from jrigid.ensemble import storage

ROOT = pathlib.Path(__file__).resolve().parents[1]
# The test functions travel to the workers by value (the workers cannot import tests/).
cloudpickle.register_pickle_by_value(test_ensemble)
cloudpickle.register_pickle_by_value(sys.modules[__name__])


def slow_rotor(member):
    """``rotor`` plus a host-side pause per member, so a sweep lasts a few seconds."""
    jax.debug.callback(lambda: time.sleep(0.1))
    return rotor(member)


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
        worker_class=distributed.Nanny,
    )
    with cluster, distributed.Client(cluster) as c:
        yield c


def test_cluster_is_bit_identical_to_in_process(tmp_path, client):
    inputs = rotor_inputs(23)
    info: dict = {}
    out = ensemble.run(rotor, inputs, chunk_size=5, out_dir=tmp_path, progress=False,
                       info=info, executor=client.get_executor(),
                       compile_cache=str(tmp_path / "cache"))
    assert_identical(out, straight(rotor, inputs))
    assert info["chunks_computed"] == 5 and sum(w["chunks"] for w in info["workers"].values()) == 5
    assert all(":" in w for w in info["workers"])  # host:pid of the workers, not this process
    assert str(os.getpid()) not in {w.split(":")[-1] for w in info["workers"]}
    # the workers wrote the chunks, tagged for this run: a resume loads all of them
    again: dict = {}
    resumed = ensemble.run(rotor, inputs, chunk_size=5, out_dir=tmp_path, progress=False,
                           info=again)
    assert again["chunks_loaded"] == 5 and again["chunks_computed"] == 0
    assert_identical(resumed, out)
    with pytest.raises(ValueError, match="devices is for the in-process run"):
        ensemble.run(rotor, inputs, executor=client.get_executor(), devices=jax.devices())
    with pytest.raises(ValueError, match="concurrent.futures.Executor"):
        ensemble.run(rotor, inputs, executor=client)


def test_simulate_many_on_cluster_equals_in_process(tmp_path, client):
    rng = np.random.default_rng(4)
    omegas = rng.normal(size=(12, 3))
    states = jax.vmap(lambda w: initial.from_omega(None, w))(jnp.asarray(omegas))
    scene = Scene(RigidBody(jnp.asarray([1.0, 2.0, 3.0])))
    ts = np.linspace(0.0, 20.0, 3)
    kwargs = dict(chunk_size=4, progress=False)
    local = ensemble.simulate_many(scene, states, ts, **kwargs)
    info: dict = {}
    remote = ensemble.simulate_many(scene, states, ts, executor=client.get_executor(),
                                    out_dir=tmp_path, info=info,
                                    compile_cache=str(tmp_path / "cache"), **kwargs)
    assert_identical(remote, local)
    assert np.all(remote["result"] == 0)


def test_worker_killed_mid_sweep_loses_nothing(tmp_path, client):
    pids = set(client.run(os.getpid).values())
    assert len(pids) == 2
    inputs = rotor_inputs(48)
    box: dict = {}

    def sweep():
        try:
            box["out"] = ensemble.run(slow_rotor, inputs, chunk_size=4, out_dir=tmp_path,
                                      progress=False, executor=client.get_executor(),
                                      info=box.setdefault("info", {}))
        except BaseException as err:  # noqa: BLE001 - reported below
            box["error"] = err

    thread = threading.Thread(target=sweep)
    thread.start()
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob("chunk_*.npz")):
        assert thread.is_alive(), box.get("error")
        assert time.monotonic() < deadline, "no chunk written within 120 s"
        time.sleep(0.02)
    victim = sorted(pids)[0]
    os.kill(victim, signal.SIGKILL)  # a worker dies in the middle of the sweep
    thread.join(timeout=240)
    assert not thread.is_alive() and "error" not in box, box.get("error")
    assert_identical(box["out"], straight(rotor, inputs))
    assert len(list(tmp_path.glob("chunk_*.npz"))) == 12
    assert f":{victim}" not in "".join(box["info"]["workers"]) or len(box["info"]["workers"]) > 1
    # the nanny restarted the killed worker: the cluster has two workers again
    deadline = time.monotonic() + 60
    while len(client.scheduler_info()["workers"]) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)


_DRIVER = """
import sys, time, jax
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, {tests!r})
import distributed
from test_distributed import slow_rotor
from test_ensemble import rotor_inputs
from jrigid import ensemble
with distributed.Client({address!r}) as client:
    ensemble.run(slow_rotor, rotor_inputs(40), chunk_size=4, out_dir={out!r}, progress=False,
                 executor=client.get_executor())
"""


def test_killed_driver_resumes_and_second_driver_is_refused(tmp_path, client):
    out_dir = tmp_path / "run"
    code = _DRIVER.format(tests=str(ROOT / "tests"), address=client.scheduler.address,
                          out=str(out_dir))
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "JAX_PLATFORMS": "cpu"})
    inputs = rotor_inputs(40)
    try:
        deadline = time.monotonic() + 120
        while len(list(out_dir.glob("chunk_*.npz"))) < 2:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no chunks written within 120 s"
            time.sleep(0.02)
        # a second driver on the same folder is refused while the first one runs
        with pytest.raises(ValueError, match=r"in use by another run \(host .*pid"):
            ensemble.run(rotor, inputs, chunk_size=4, out_dir=out_dir, progress=False)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    finished = {p.name: p.stat().st_mtime_ns for p in out_dir.glob("chunk_*.npz")}
    assert 2 <= len(finished) <= 10
    info: dict = {}
    out = ensemble.run(rotor, inputs, chunk_size=4, out_dir=out_dir, progress=False,
                       info=info, executor=client.get_executor())
    assert info["chunks_loaded"] >= len(finished)
    assert info["chunks_loaded"] + info["chunks_computed"] == 10
    assert_identical(out, straight(rotor, inputs))
    for name, mtime in finished.items():  # finished chunks were loaded, not rewritten
        assert (out_dir / name).stat().st_mtime_ns == mtime


def test_process_pool_is_bit_identical_and_resumes(tmp_path):
    """A standard-library ``ProcessPoolExecutor`` (spawned workers) as the executor."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    inputs = rotor_inputs(12)
    info: dict = {}
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=2, mp_context=ctx) as pool:
        out = ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False,
                           info=info, executor=pool)
    assert_identical(out, straight(rotor, inputs))
    assert info["chunks_computed"] == 3
    assert str(os.getpid()) not in {w.split(":")[-1] for w in info["workers"]}
    again: dict = {}
    resumed = ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False,
                           info=again)
    assert again["chunks_loaded"] == 3 and again["chunks_computed"] == 0
    assert_identical(resumed, out)


def test_chunk_file_copied_to_another_index_is_not_loaded(tmp_path):
    inputs = rotor_inputs(8)
    ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False)
    (tmp_path / "chunk_00001.npz").write_bytes((tmp_path / "chunk_00000.npz").read_bytes())
    info: dict = {}
    out = ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False, info=info)
    assert info["chunks_loaded"] == 1 and info["chunks_computed"] == 1
    assert_identical(out, straight(rotor, inputs))
    # nor a chunk of another run (other inputs, same shapes) in the right place
    other = tmp_path / "other"
    ensemble.run(rotor, rotor_inputs(8, seed=9), chunk_size=4, out_dir=other, progress=False)
    (tmp_path / "chunk_00000.npz").write_bytes((other / "chunk_00000.npz").read_bytes())
    out = ensemble.run(rotor, inputs, chunk_size=4, out_dir=tmp_path, progress=False, info=info)
    assert info["chunks_loaded"] == 1 and info["chunks_computed"] == 1
    assert_identical(out, straight(rotor, inputs))
    with np.load(tmp_path / "chunk_00000.npz") as data:
        assert str(data[storage.TAG]).startswith("0:")


_JAX_DISTRIBUTED = """
import sys
import jax
jax.config.update("jax_cpu_collectives_implementation", "gloo")
jax.distributed.initialize(coordinator_address="127.0.0.1:{port}", num_processes=2,
                           process_id={rank})
jax.config.update("jax_enable_x64", True)
import numpy as np
sys.path.insert(0, {tests!r})
from test_ensemble import rotor, rotor_inputs
from jrigid import ensemble
assert len(jax.devices()) == 2 and len(jax.local_devices()) == 1
info = {{}}
out = ensemble.run(rotor, rotor_inputs(23), chunk_size=10, progress=False, info=info,
                   out_dir={out!r})
assert info["n_devices"] == 2 and info["chunks_computed"] == 3, info
np.savez({result!r}, **out)
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_jax_distributed_two_processes(tmp_path):
    """The one-global-mesh route: two processes, one CPU device each, gloo collectives."""
    port = _free_port()
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _JAX_DISTRIBUTED.format(
                port=port, rank=rank, tests=str(ROOT / "tests"), out=str(tmp_path / "run"),
                result=str(tmp_path / f"result_{rank}.npz"))],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "JAX_PLATFORMS": "cpu"},
        )
        for rank in (0, 1)
    ]
    for proc in procs:
        _, err = proc.communicate(timeout=240)
        assert proc.returncode == 0, err[-3000:]
    reference = straight(rotor, rotor_inputs(23))
    for rank in (0, 1):  # every process gets every member
        with np.load(tmp_path / f"result_{rank}.npz") as data:
            assert_identical({k: data[k] for k in data.files}, reference)
    # process 0 wrote the run; it resumes in one process
    info: dict = {}
    out = ensemble.run(rotor, rotor_inputs(23), chunk_size=10, out_dir=tmp_path / "run",
                       progress=False, info=info)
    assert info["chunks_loaded"] == 3
    assert_identical(out, reference)


_SWEEP_EXPERIMENT = '''"""A tiny ensemble sweep that takes its executor from the command line."""
import numpy as np
from jrigid import ensemble


def main(out_dir, quick=False, *, n=12, workers=0, scheduler=""):
    import jax
    jax.config.update("jax_enable_x64", True)
    info = {}
    with ensemble.executor(workers=workers, scheduler=scheduler) as pool:
        out = ensemble.run(lambda m: {"y": m["x"] ** 2}, {"x": np.arange(n, dtype=float)},
                           chunk_size=3, out_dir=out_dir / "chunks", executor=pool, info=info,
                           progress=False)
    return {"y": out["y"].tolist(), "workers": sorted(info.get("workers", {}))}
'''


def test_cli_takes_workers_and_scheduler(tmp_path, monkeypatch, capsys, client):
    import json

    from jrigid import cli, registry

    folder = tmp_path / "experiments"
    folder.mkdir()
    (folder / "sweep.py").write_text(_SWEEP_EXPERIMENT)
    (folder / "plain.py").write_text('"""No executor."""\ndef main(out_dir, quick=False):\n'
                                     '    return {}\n')
    monkeypatch.setenv(registry.ENV_VAR, str(folder))
    expected = [float(x) ** 2 for x in range(12)]
    for option in (["--scheduler", client.scheduler.address], ["--workers", "2"]):
        out = tmp_path / option[0].strip("-")
        assert cli.main(["run", "sweep", "--out", str(out), *option]) == 0
        numbers = json.loads((out / "numbers.json").read_text())
        assert numbers["y"] == expected
        assert len(numbers["workers"]) >= 1
        assert str(os.getpid()) not in {w.split(":")[-1] for w in numbers["workers"]}
    for argv, message in [
        (["run", "plain", "--workers", "2"], "does not run on an executor"),
        (["run", "sweep", "--workers", "0"], "--workers must be at least 1"),
        (["run", "sweep", "--workers", "2", "--scheduler", "tcp://x:1"], "not both"),
        (["run", "sweep", "workers=2"], "set with --workers"),
    ]:
        with pytest.raises(SystemExit) as exc:
            cli.main([*argv, "--out", str(tmp_path / "never")])
        assert exc.value.code == 2
        assert message in capsys.readouterr().err
