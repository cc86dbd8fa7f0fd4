"""The thesis's discrete track-terrain model (docs/model.md §1-5) as pure JAX functions.

Array convention (all modules): per-element arrays are ``(2, N, *batch)`` (track, contact point),
per-track arrays ``(2, *batch)`` (left, right), body scalars ``(*batch)``. A single vehicle has
``batch = ()``; a batch of vehicles puts the vehicle index on the *last* axis (docs/model.md §6), and
parameter leaves may be scalars or ``(*batch)`` arrays, which then broadcast by NumPy's rules.
"""
