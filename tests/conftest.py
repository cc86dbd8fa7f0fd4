"""Hypothesis profiles: ``ci`` (default, modest budgets) and ``thorough`` (``HYPOTHESIS_PROFILE=thorough``)."""

import os

try:
    from hypothesis import HealthCheck, settings
except ImportError:  # hypothesis is in the ``test`` extra; the property tests skip without it
    pass
else:
    common = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
                  derandomize=False, print_blob=True)
    settings.register_profile("ci", max_examples=8, **common)
    settings.register_profile("thorough", max_examples=200, **common)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
