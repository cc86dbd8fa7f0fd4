import numpy as np
import pytest

import trackenv.effects as fx


def test_registry_and_defaults_in_bounds():
    assert set(fx.EFFECT_IDS) == {"slip_sinkage", "lateral_friction_radius", "internal_resistance",
                                  "grouser_stiction", "pitch_load_transfer", "sensor_artifacts"}
    for i, cls in fx.EFFECTS.items():
        e = fx.get_effect(i)
        assert isinstance(e, cls) and e.id == i and cls.__doc__
        for k, (lo, hi) in cls.bounds.items():
            assert lo <= float(getattr(e, k)) <= hi, (i, k)


def test_overrides_and_errors():
    e = fx.get_effect("internal_resistance", b1=0.05)
    assert float(e.b1) == pytest.approx(0.05) and float(e.b0) == pytest.approx(0.88)
    with pytest.raises(ValueError, match="known ids"):
        fx.get_effect("nope")
    with pytest.raises(ValueError, match="b0"):
        fx.get_effect("internal_resistance", b0=-1.0)
    with pytest.raises(ValueError, match="max_sinkage"):
        fx.get_effect("slip_sinkage", max_sinkage=0.5)


def test_env_and_replay_resolve():
    from trackenv.replay import resolve_effects
    (e,) = resolve_effects(["internal_resistance"])
    assert e.id == "internal_resistance"
    import gymnasium as gym

    import trackenv.envs  # noqa: F401
    env = gym.make("trackenv/ZeroRadiusTurn-v0", effects=["slip_sinkage"])
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, *_ = env.step(env.action_space.sample())
    assert np.all(np.isfinite(obs))
    env.close()
