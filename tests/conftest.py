"""Test-wide setup: Hypothesis profiles (``ci`` by default, ``thorough`` with ``HYPOTHESIS_PROFILE=thorough``),
JAX's compiled programs released after each test module, and the disk cache of compiled programs off."""

import gc
import os

import pytest

# the command line's disk cache of compiled programs stays off in tests (no writes to the user's home);
# tests/test_compile_cache.py checks it with its own directories
os.environ.setdefault("TRACKENV_COMPILATION_CACHE", "off")

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


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs(request):
    """Drop JAX's compiled programs after each test module.

    Every XLA:CPU executable holds a few memory mappings of JIT code, and a test worker that runs hundreds of
    modules would otherwise accumulate tens of thousands of them; at the kernel's ``vm.max_map_count``
    (65 530 by default) LLVM's next code allocation fails and the process aborts inside a compile.
    """
    yield
    import jax

    def mappings():
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f)

    log = os.environ.get("TRACKENV_TEST_MAPS")  # diagnostics: mappings per module, before and after
    before = mappings() if log else 0
    jax.clear_caches()
    gc.collect()
    if log:
        with open(log, "a") as f:
            f.write(f"{os.getpid()} {request.module.__name__} {before} {mappings()}\n")
