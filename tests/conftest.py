"""Hypothesis profiles: ``ci`` (default, modest budgets) and ``thorough`` (``HYPOTHESIS_PROFILE=thorough``)."""

import os

try:
    from hypothesis import HealthCheck, settings
except ImportError:  # hypothesis is in the ``test`` extra; the property tests skip without it
    pass
else:
    common = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
                  print_blob=True)
    # ci: the same examples on every run (no flaky CI); thorough: new random examples each run
    settings.register_profile("ci", max_examples=8, derandomize=True, database=None, **common)
    settings.register_profile("thorough", max_examples=200, **common)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
