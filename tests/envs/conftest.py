import warnings

import pytest


@pytest.fixture(autouse=True)
def _quiet_action_space_advice():
    # Gymnasium and SB3 recommend a [-1, 1] action space; ours is in volts by design (normalize_action=True
    # gives [-1, 1]). Everything else stays visible.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
        yield
