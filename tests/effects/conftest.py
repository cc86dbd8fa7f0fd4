import trackenv as te

ZRT = [[0, 0, 0], [0.3, 12.0, -12.0], [30, 12.0, -12.0]]


def sim(terrain, effects=(), rows=ZRT, t_end=4.0, **kw):
    p = te.load_params(terrain, effects=tuple(effects))
    return te.simulate(p, te.VoltageProfile.from_breakpoints(rows), t_end, substep=0.001, **kw)
