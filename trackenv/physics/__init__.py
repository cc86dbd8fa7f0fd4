"""The thesis's discrete track-terrain model (docs/model.md §1-5) as pure JAX functions.

Array convention (all modules): per-element arrays are ``(2, N, *batch)`` (track, contact point),
per-track arrays ``(2, *batch)`` (left, right), per-patch arrays ``(1, P, *batch)`` (the P contact patches
of a side: 1 for a track, docs/model.md §1.1), body scalars ``(*batch)``. A single vehicle has
``batch = ()``; a batch of vehicles puts the vehicle index on the *last* axis (docs/model.md §6), and
parameter leaves may be scalars or ``(*batch)`` arrays, which then broadcast by NumPy's rules.

The public functions carry these shapes as jaxtyping annotations, e.g. ``Float[Array, " 2 N *b"]``
per element, ``Float[Array, " 2 *b"]`` per track, ``Float[Array, " 3 *b"]`` for the pose and the body
velocity, ``"*#b"`` where a parameter leaf may be a scalar (broadcastable), ``"*s"`` for elementwise
laws (the leading space keeps linters from reading the string as a forward reference). They are
annotations only: nothing checks them at run time, and they change nothing in the compiled program
(tests/test_typing.py keeps them complete).
"""
