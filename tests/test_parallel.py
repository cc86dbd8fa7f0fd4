"""Batches split across the host devices (trackenv.parallel) give the same trajectories as one device."""

import importlib
import os

import jax
import numpy as np
import pytest

import trackenv as te
from trackenv import parallel
from trackenv.envs.vector import TrackVectorEnv


def test_one_host_device_per_core():
    # trackenv is imported before the first JAX computation of the test process, so it sets them up
    if "TRACKENV_HOST_DEVICES" in os.environ:
        pytest.skip("device count set by the environment")
    assert len(parallel.cpu_devices()) == min(parallel._cores(), parallel.MAX_HOST_DEVICES)


def test_split_count_rule(monkeypatch):
    n = len(parallel.cpu_devices())
    if n < 2:
        pytest.skip("one host device")
    m = parallel.MIN_PER_DEVICE
    assert parallel.split_count(1) == 1
    assert parallel.split_count(n * m - n) == 1  # too few per core
    assert parallel.split_count(n * m) == n
    assert parallel.split_count(n * m + 1) == 1  # does not divide evenly


def _count_splits(monkeypatch) -> list:
    """Record the batch size of every simulation that trackenv.simulate splits over the devices."""
    sim = importlib.import_module("trackenv.simulate")  # the module (te.simulate is the function)
    seen, shard = [], sim.shard

    def counting(tree, batch, axis=-1, min_per_device=None):
        seen.append(batch)
        return shard(tree, batch, axis, min_per_device)
    monkeypatch.setattr(sim, "shard", counting)
    return seen


def test_split_simulation_matches_one_device(monkeypatch):
    if len(parallel.cpu_devices()) < 2:
        pytest.skip("one host device")
    monkeypatch.setattr(parallel, "MIN_PER_DEVICE", 2)
    b = 4
    rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [0.8, 16, 6], [1.0, 0, 0]], float)
    volts = rows[:, 1:, None] * np.linspace(0.8, 1.2, b)[None, None]
    prof = te.VoltageProfile.from_arrays(rows[:, 0], volts)
    params = te.replace(te.load_params("dry_sand"), **{"terrain.cohesion": np.linspace(500.0, 1500.0, b)})
    placed = _count_splits(monkeypatch)
    split = te.simulate(params, prof, 1.0, substep=0.001)
    assert placed == [b]  # split over the devices ...
    assert len(split.channels["x"].sharding.device_set) == 1  # ... and gathered back onto one
    monkeypatch.setattr(parallel, "MIN_PER_DEVICE", 10**9)
    one = te.simulate(params, prof, 1.0, substep=0.001)
    assert placed == [b]
    for k in ("speed_ideal", "yaw_rate", "i_left", "x", "y"):
        a, c = np.asarray(split.channels[k]), np.asarray(one.channels[k])
        assert np.abs(a[-1]).max() > 1e-3  # the vehicles moved
        np.testing.assert_allclose(a, c, rtol=1e-5, atol=1e-6 * np.abs(c).max())



def test_a_large_batch_runs_in_equal_chunks_and_matches_the_whole_batch(monkeypatch):
    """Above ``MAX_PER_DEVICE`` vehicles per core a batch runs as equal chunks (padded with its last vehicle),
    one program for all of them; each vehicle keeps its own voltages and parameters, in order, and the state,
    channels and flags equal the whole batch's to float rounding."""
    sim = importlib.import_module("trackenv.simulate")
    n = len(parallel.cpu_devices())
    monkeypatch.setattr(parallel, "MAX_PER_DEVICE", 4)
    monkeypatch.setattr(parallel, "SHARE_ALIGN", 2)
    b = 9 * n + 1  # three chunks of 4 n vehicles after padding (each core's share rounded up to 4)
    rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [0.8, 16, 6], [1.0, 0, 0]], float)
    volts = rows[:, 1:, None] * np.linspace(0.6, 1.2, b)[None, None]
    prof = te.VoltageProfile.from_arrays(rows[:, 0], volts)
    params = te.replace(te.load_params("dry_sand"), **{"vehicle.mass": np.linspace(17.0, 26.0, b)})
    runs, split = [], sim._split

    def counting(params, profile, *args):
        runs.append(sim.profile_values(profile).shape[-1])
        return split(params, profile, *args)
    monkeypatch.setattr(sim, "_split", counting)
    chunked = te.simulate(params, prof, 1.0, substep=0.001, on_divergence="flag")
    assert runs == [4 * n] * 3
    monkeypatch.setattr(parallel, "MAX_PER_DEVICE", 10**9)
    whole = te.simulate(params, prof, 1.0, substep=0.001, on_divergence="flag")
    assert runs == [4 * n] * 3 + [b]
    assert chunked.channels["x"].shape == whole.channels["x"].shape == (21, b)
    assert np.ptp(np.asarray(whole.channels["x"])[-1]) > 0.05  # the vehicles differ
    for k in ("speed_ideal", "yaw_rate", "i_left", "x", "y"):
        a, c = np.asarray(chunked.channels[k]), np.asarray(whole.channels[k])
        np.testing.assert_allclose(a, c, rtol=1e-5, atol=1e-5 * np.abs(c).max(), err_msg=k)
    for a, c in zip(jax.tree.leaves(chunked.state), jax.tree.leaves(whole.state)):
        assert a.shape == c.shape
        np.testing.assert_allclose(np.asarray(a), np.asarray(c), rtol=1e-4, atol=1e-4 * (np.abs(np.asarray(c)).max() + 1e-12))
    assert not np.asarray(chunked.diverged).any() and chunked.diverged.shape == (b,)

def test_diagnosis_batches_split_over_the_cores_with_an_odd_batch_padded(monkeypatch):
    """The diagnosis's simulations (trackenv.simulate.simulate_on_cores) split an odd batch over the devices
    by padding it with a copy of its last vehicle; the outputs are the unsplit batch's, padding dropped."""
    from trackenv.compare import stack_trees
    from trackenv.simulate import simulate_batch, simulate_on_cores
    if len(parallel.cpu_devices()) < 2:
        pytest.skip("one host device")
    b = 5  # odd: not divisible over two devices
    rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [0.8, 16, 6], [1.0, 0, 0]], float)
    volts = rows[:, 1:, None] * np.linspace(0.8, 1.2, b)[None, None]
    prof = te.VoltageProfile(jax.numpy.asarray(rows[:, 0], np.float32), jax.numpy.asarray(volts, np.float32))
    base = te.load_params("dry_sand")
    params = stack_trees([te.replace(base, **{"terrain.cohesion": c}) for c in np.linspace(500.0, 1500.0, b)])
    monkeypatch.setattr(parallel, "MIN_PER_DEVICE", 2)
    placed = _count_splits(monkeypatch)
    traj = simulate_on_cores(params, prof, 50, 0.02, 20)
    assert placed == [b + 1]  # padded to 6, three per device
    assert traj.channels["x"].shape == (51, b) and traj.diverged.shape == (b,)
    one = simulate_batch(params, prof, 50, 0.02, 20)
    assert not np.asarray(traj.diverged).any()
    for k in ("speed_ideal", "yaw_rate", "i_left", "x", "y"):
        a, c = np.asarray(traj.channels[k]), np.asarray(one.channels[k])
        assert np.abs(a[-1]).max() > 1e-3  # the vehicles moved
        assert np.abs(a[-1, 0] - a[-1, -1]) > 1e-4  # and differently: a wrong column would show
        # 3 vehicles per device against 5 on one: programs of other widths, float32 rounding of ~1e-6 of the
        # channel's peak at the stop; a wrong or shifted column differs by more than 1e-4 (above)
        np.testing.assert_allclose(a, c, rtol=1e-5, atol=1e-5 * np.abs(c).max())
    for x, y in zip(jax.tree.leaves(traj.state), jax.tree.leaves(one.state)):
        assert x.shape == y.shape


def test_split_vector_env_matches_one_device(monkeypatch):
    """The batched program (XLA partitions it) agrees to rounding; the default row loop (the same
    single-device program on each device's rows) bit for bit."""
    if len(parallel.cpu_devices()) < 2:
        pytest.skip("one host device")
    a = np.array([[11.8, 11.8], [6, 6], [20, 20], [0, 3]], np.float32)
    for batching, threshold in (("vmap", "MIN_ENVS_PER_DEVICE"), ("loop", "MIN_ROWS_PER_DEVICE")):
        out = {}
        for per in (2, 10**9):
            monkeypatch.setattr(parallel, threshold, per)
            venv = TrackVectorEnv("go_stop", 4, autoreset_mode="same_step", substep=0.002, physics_batching=batching)
            venv.reset(seed=3)
            for _ in range(3):
                obs, rew, *_ = venv.step(a)
            out[per] = (obs, rew, jax.tree.leaves(venv._sf)[0].sharding.device_set)
        assert len(out[2][2]) == 2 and len(out[10**9][2]) == 1, batching
        if batching == "loop":
            np.testing.assert_array_equal(out[2][0], out[10**9][0])
            np.testing.assert_array_equal(out[2][1], out[10**9][1])
        else:
            np.testing.assert_allclose(out[2][0], out[10**9][0], rtol=1e-5, atol=1e-5)
            np.testing.assert_allclose(out[2][1], out[10**9][1], rtol=1e-5, atol=1e-5)


def test_split_vector_env_sums_in_the_form_of_each_share(monkeypatch):
    """160 environments split in two: the whole batch would sum in XLA's reduce form, each device's 80 in the
    unrolled one (``sums.Partitioned``); the split native program agrees with the one-device program."""
    from trackenv.physics import sums

    if len(parallel.cpu_devices()) < 2:
        pytest.skip("one host device")
    n = sums.UNROLL_MAX
    assert not sums.unrolled(n) and sums.unrolled(n // 2)
    a = np.tile(np.array([[11.8, 11.8], [16, 6]], np.float32), (n // 2, 1))
    out = {}
    for per in (n // 2, 10**9):
        monkeypatch.setattr(parallel, "MIN_ENVS_PER_DEVICE", per)
        venv = TrackVectorEnv("j_turn", n, autoreset_mode="same_step", substep=0.002, physics_batching="native")
        venv.reset(seed=5)
        for _ in range(3):
            obs, rew, *_ = venv.step(a)
        out[per] = (obs, rew, venv._parts, jax.tree.leaves(venv._sf)[0].sharding.device_set)
    assert out[n // 2][2] == 2 and len(out[n // 2][3]) == 2 and out[10**9][2] == 1
    np.testing.assert_allclose(out[n // 2][0], out[10**9][0], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(out[n // 2][1], out[10**9][1], rtol=1e-5, atol=1e-5)


def test_a_large_vector_env_steps_in_equal_chunks_and_matches_one_program(monkeypatch):
    """Above ``MAX_PER_DEVICE`` environments per core the batched program steps equal chunks (the last padded
    with copies of its last environment), each split over the cores; observations, rewards, flags, the
    autoreset's final observations, a masked reset and the state keep every environment in its place and
    equal the one program's to float rounding."""
    from trackenv.envs import vector

    n = len(parallel.cpu_devices())
    monkeypatch.setattr(parallel, "SHARE_ALIGN", 2)
    monkeypatch.setattr(parallel, "MIN_ENVS_PER_DEVICE", 2)
    b = 9 * n + 1  # three chunks of 4 n environments after padding
    a = np.stack([np.linspace(4.0, 16.0, b), np.linspace(14.0, 2.0, b)], axis=1).astype(np.float32)
    mask = np.arange(b) % 3 == 1
    out, calls = {}, []
    step = vector.TrackVectorEnv._joined

    def counting(self, outs):
        outs = list(outs)
        calls.append([o[0].shape[0] for o in outs])
        return step(self, outs)
    monkeypatch.setattr(vector.TrackVectorEnv, "_joined", counting)
    for per in (4, 10**9):
        monkeypatch.setattr(parallel, "MAX_PER_DEVICE", per)
        venv = vector.TrackVectorEnv("go_stop", b, autoreset_mode="same_step", substep=0.002, physics_batching="vmap",
                                     max_time=0.15)
        venv.reset(seed=3)
        steps = [venv.step(a) for _ in range(3)]  # the episodes end at the third step
        obs_m, _ = venv.reset(options={"reset_mask": mask})
        out[per] = steps, obs_m, venv.state, venv._chunk
    assert out[4][3] == 4 * n and out[10**9][3] == b
    assert calls[:5] == [[4 * n] * 3] * 5 and calls[5:] == [[b]] * 5
    (chunked, obs_c, state_c, _), (whole, obs_w, state_w, _) = out[4], out[10**9]
    assert np.ptp(whole[1][1]) > 1e-3  # the environments differ: a shifted row would show
    for (oc, rc, tc, uc, ic), (ow, rw, tw, uw, iw) in zip(chunked, whole):
        assert oc.shape == ow.shape == (b, ow.shape[1])
        np.testing.assert_allclose(oc, ow, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(rc, rw, rtol=1e-5, atol=1e-5)
        np.testing.assert_array_equal(tc, tw)
        np.testing.assert_array_equal(uc, uw)
        np.testing.assert_allclose(ic["energy"], iw["energy"], rtol=1e-5, atol=1e-6)
    assert chunked[-1][3].all() and "final_obs" in chunked[-1][4]  # every episode ended at the third step
    np.testing.assert_allclose(np.stack(chunked[-1][4]["final_obs"]), np.stack(whole[-1][4]["final_obs"]), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(obs_c, obs_w, rtol=1e-5, atol=1e-5)
    for x, y in zip(jax.tree.leaves(state_c), jax.tree.leaves(state_w)):
        assert x.shape == y.shape and x.shape[0] == b
        if y.size:
            np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-4 * (np.abs(y).max() + 1e-12))


def test_batches_are_chunked_on_a_cpu_only(monkeypatch):
    """Chunks keep a CPU core's share in its cache; an accelerator gets the whole batch in one program."""
    from trackenv.parallel import chunk_size

    n = len(parallel.cpu_devices())
    assert parallel.chunk_limit() == parallel.MAX_PER_DEVICE
    assert chunk_size(n * parallel.MAX_PER_DEVICE) == n * parallel.MAX_PER_DEVICE  # at the limit: one chunk
    big = 4096 * n
    c = chunk_size(big)
    assert c < big and c % (n * parallel.SHARE_ALIGN) == 0 and c <= n * parallel.MAX_PER_DEVICE
    assert -(-big // c) * c - big < c  # the padding is less than one chunk
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert parallel.chunk_limit() is None and chunk_size(big) == big


def _simulate_script(out):
    return ("import numpy as np, trackenv as te\n"
            "rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [1.0, 16, 6], [1.5, 0, 0], [2.0, 0, 0]], float)\n"
            "prof = te.VoltageProfile.from_arrays(rows[:, 0], rows[:, 1:])\n"
            "tr = te.simulate(te.load_params('dry_sand'), prof, 2.0)\n"
            f"np.savez({str(out)!r}, **{{k: np.asarray(v) for k, v in tr.channels.items()}})\n")


def test_small_loops_are_one_kernel_and_change_nothing_but_speed(tmp_path):
    """One vehicle's substep loop and a 64-vehicle batch's are emitted as one kernel (XLA's small-while-loop
    call), a batch of 256 (whose contact sums are a library reduce, ``sums.UNROLL_MAX``) is not; the
    trajectory equals the one without the option (a fresh process with it switched off)."""
    import subprocess
    import sys

    from trackenv.physics.model import initial_state
    from trackenv.simulate import simulate_core

    if "xla_cpu_small_while_loop_byte_threshold" not in os.environ.get("XLA_FLAGS", ""):
        pytest.skip("small-loop option not set (XLA_FLAGS or TRACKENV_SMALL_LOOP_BYTES)")
    params = te.load_params("dry_sand")

    def hoisted(batch):
        rows = np.array([[0, 0, 0], [1.0, 11.8, 11.8]], float)
        v = rows[:, 1:] if batch is None else np.repeat(rows[:, 1:, None], batch, axis=2)
        prof = te.VoltageProfile.from_arrays(rows[:, 0], v)
        s0 = initial_state(params, () if batch is None else (batch,))
        return parallel.substep_loop_is_one_kernel(jax.jit(
            simulate_core, static_argnames=("n_steps", "dt", "substeps", "t0", "unroll")).lower(
            params, prof, s0, n_steps=4, dt=0.05, substeps=100).compile())

    assert hoisted(None)
    assert hoisted(64)
    assert not hoisted(256)
    on, off = tmp_path / "on.npz", tmp_path / "off.npz"
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    for path, extra in ((on, {}), (off, {"TRACKENV_SMALL_LOOP_BYTES": "0"})):
        subprocess.run([sys.executable, "-c", _simulate_script(path)], check=True, env={**env, **extra})
    a, b = np.load(on), np.load(off)
    assert np.abs(a["speed_ideal"]).max() > 0.3 and np.abs(a["yaw_rate"]).max() > 0.1  # it drove and turned
    for k in ("speed_ideal", "yaw_rate", "i_left", "i_right", "x", "y"):
        np.testing.assert_allclose(a[k], b[k], rtol=1e-5, atol=1e-6 * np.abs(b[k]).max(), err_msg=k)


@pytest.mark.parametrize("env_name", ["GoStop-v0", "JTurn-v0", "LaneChange-v0", "ZeroRadiusTurn-v0"])
def test_env_step_is_one_kernel(env_name):
    """The env's compiled step keeps what it derives from the parameters inside its row loop: the program's
    entry computation holds a handful of kernels, not the ~50 that loop-invariant code motion lifts out of
    the loop without the barrier in ``rows._row_params`` (each a separate task of XLA's CPU runtime, every
    step). With small loops as one kernel, the row loop with the whole step in it is one call on every task,
    the path tasks (whose state carries the reference polyline) included."""
    import gymnasium as gym

    env = gym.make(f"trackenv/{env_name}").unwrapped
    env.reset(seed=0)
    args = (env._sf, env._si, np.zeros((1, 2), np.float32), env._disabled, env._one, env._pf, env._pi)
    text = env._step_fn.lower(*args).compile().as_text()
    entry = text[text.index("\nENTRY"):]
    entry = entry[: entry.index("\n}")]
    assert entry.count(" fusion(") <= 10, entry
    if "xla_cpu_small_while_loop_byte_threshold" in os.environ.get("XLA_FLAGS", ""):
        assert "xla_cpu_small_call" in entry and " while(" not in entry
