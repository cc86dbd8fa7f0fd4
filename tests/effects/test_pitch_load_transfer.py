import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.effects import get_effect
from trackenv.effects.pitch_load_transfer import pitch_gradient
from trackenv.physics import loads
from trackenv.physics.geometry import contact_area, contact_x

from .conftest import sim


def test_gradient_moment_balance():
    veh = te.load_params("dry_sand").vehicle
    area, x = contact_area(veh, 0), contact_x(veh, 0)
    a = jnp.asarray(-2.0)  # braking
    px = pitch_gradient(veh.mass, veh.cg_height, area, x, a)
    n = loads.normal_loads(veh, jnp.asarray(0.0), jnp.asarray(0.0), 0, pitch_gradient=px)
    assert float(n.sum()) == pytest.approx(float(veh.mass) * 9.81, rel=1e-5)  # total unchanged
    moment = float((n * x).sum())
    assert moment == pytest.approx(-float(veh.mass) * -2.0 * float(veh.cg_height), rel=1e-4)  # = -m a h
    assert float(n[0, 0]) > float(n[0, -1])  # front loaded in braking
    # continuous-track limit p_x = -6 m a h / (b L^3) within the trapezoid error
    cont = -6 * float(veh.mass) * -2.0 * float(veh.cg_height) / (float(veh.track_width) * float(veh.contact_length) ** 3)
    assert float(px) == pytest.approx(cont, rel=0.02)


def test_braking_shifts_load_forward_in_simulation():
    rows = [[0, 0, 0], [0.3, 15, 15], [2.0, 15, 15], [2.1, -15, -15], [4, -15, -15]]
    e = get_effect("pitch_load_transfer")
    tr = sim("asphalt", (e,), rows, t_end=2.5)
    a = np.asarray(tr.state.extra["pitch_load_transfer"])
    t = np.asarray(tr.t)
    assert a[(t > 0.05) & (t < 0.3)].max() > 0.3  # accelerating
    assert a[(t > 2.1) & (t < 2.5)].min() < -0.5  # braking
    import jax

    from trackenv.physics.model import evaluate
    k = int(np.argmin(a))
    state = jax.tree.map(lambda v: v[k], tr.state)
    p = te.load_params("asphalt", effects=(e,))
    ev = evaluate(state, jnp.array([-15.0, -15.0]), p)
    n = np.asarray(ev.forces.normal)
    assert n[:, 0].sum() > n[:, -1].sum() * 1.05
    assert n.sum() == pytest.approx(float(p.vehicle.mass) * 9.81, rel=1e-4)
