"""A short soak of the vector env in CI (benchmarks/soak.py runs the long one; README "Reliability").

100 000 env-steps (64 environments x 1 562 steps; episodes of 1 s, so ~5 000 autoresets) with domain
randomisation and the slip_sinkage effect: no compilation after the first step, no non-finite
observation or reward, no diverged episode, and RSS growth after warm-up below 1 %.
"""

import importlib.util
from pathlib import Path

spec = importlib.util.spec_from_file_location("soak", Path(__file__).resolve().parent.parent / "benchmarks" / "soak.py")
soak = importlib.util.module_from_spec(spec)
spec.loader.exec_module(soak)


def test_short_soak():
    res = soak.run_soak(100_000, 64)
    assert res["steps"] >= 99_900
    assert res["episodes_finished"] > 2_500  # autoreset really ran, many times
    assert res["randomised_mass_spread_kg"] > 0.5  # domain randomisation is on
    assert res["compilations_first_step"] > 0  # the listener sees compilations at all
    assert res["compilations_after_first_step"] == 0, res
    assert res["nonfinite_steps"] == 0 and res["diverged_episodes"] == 0, res
    assert res["rss_growth"] < 0.01, res
