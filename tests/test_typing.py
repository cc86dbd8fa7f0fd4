"""Shape annotations of the numerical core: every public function keeps them.

The modules of ``trackenv.physics`` and ``trackenv.integrate`` annotate their array arguments and
results with jaxtyping shapes (``Float[Array, " 2 N *b"]``: track, contact point, trailing batch axes;
the leading space is jaxtyping's convention for linters). The annotations are documentation only:
nothing checks them at run time, so this test makes sure they cannot silently go missing or stop
resolving:

1. every parameter of every public function (defined in the module, name without a leading underscore)
   and its return are annotated, and the annotations resolve (``typing.get_type_hints``);
2. every annotation is a jaxtyping array type, a known non-array type (the parameter pytrees, the
   state and the other model records, ``int``), or a union, tuple or callable built from these, so an
   array is never annotated as a bare ``jax.Array``, ``object`` or ``Any``;
3. the shape strings use the documented dimension names only;
4. the functions are not wrapped by a run-time checker (annotations only: no change at run or compile
   time).

``EXCEPTIONS`` lists (module, function) pairs exempt from 1-3, each with its reason.
"""

from __future__ import annotations

import inspect
import types
import typing
from collections.abc import Callable, Sequence

import jaxtyping
import numpy as np
import pytest

from trackenv import integrate
from trackenv.params import InternalResistance, Params, Terrain, Vehicle
from trackenv.physics import body, contact, geometry, loads, model, motor, sums, terramechanics

MODULES = [terramechanics, geometry, contact, loads, body, motor, model, sums, integrate]

# (module name, function name) -> why it has no (complete) array annotation.
EXCEPTIONS: dict[tuple[str, str], str] = {}

# Non-array annotations an argument or result may have.
ALLOWED_TYPES = {
    int, bool, type(None), Vehicle, Terrain, InternalResistance, Params,
    model.State, model.Evaluation, model.PowerBalance, contact.Kinematics, contact.ContactForces,
    integrate.Coeffs,
}

# Dimension names of the shape strings (trackenv.physics docstring): 2 tracks, 3 pose/velocity
# components or ETDRK4 stages, N contact points per track, P contact patches per side, n substeps,
# *b trailing batch axes ("#": broadcastable, e.g. parameter leaves that are scalars), *s any shape of
# elementwise laws.
DIMS = {"1", "2", "3", "N", "P", "n", "*b", "*#b", "*s", "*#s", "..."}


def public_functions():
    out = []
    for module in MODULES:
        for name, fn in vars(module).items():
            if name.startswith("_") or not inspect.isfunction(fn) or fn.__module__ != module.__name__:
                continue
            out.append(pytest.param(module, name, fn, id=f"{module.__name__.rsplit('.', 1)[-1]}.{name}"))
    return out


FUNCTIONS = public_functions()


def _is_array_type(tp) -> bool:
    return isinstance(tp, type) and issubclass(tp, jaxtyping.AbstractArray)


def _is_scalar_type(tp) -> bool:
    """A Python or NumPy scalar: the members of jaxtyping's ``ArrayLike`` union besides the arrays."""
    return isinstance(tp, type) and (tp in (bool, float, complex) or issubclass(tp, np.generic))


def _problems(tp) -> list[str]:
    """Why ``tp`` is not an allowed annotation (empty list: it is)."""
    if _is_array_type(tp):
        bad = [d for d in tp.dim_str.split() if d not in DIMS]
        return [f"unknown dimension(s) {bad} in {tp.dim_str!r}"] if bad else []
    if tp in ALLOWED_TYPES or _is_scalar_type(tp):
        return []
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return [p for a in args for p in _problems(a) if a is not type(None)]
    if origin is tuple:
        return [p for a in args if a is not Ellipsis for p in _problems(a)]
    if origin is Callable:
        params, result = args
        return [p for a in (*params, result) for p in _problems(a)]
    if origin is Sequence and args == (float,):  # a pose or velocity given as a list
        return []
    return [f"{tp!r} is not a jaxtyping array annotation nor an allowed type"]


def test_modules_have_public_functions():
    names = {p.values[1] for p in FUNCTIONS}
    assert {"kinematics", "evaluate", "derivative", "advance", "advance_constant", "normal_loads"} <= names


@pytest.mark.parametrize("module, name, fn", FUNCTIONS)
def test_public_function_is_annotated(module, name, fn):
    if (module.__name__, name) in EXCEPTIONS:
        pytest.skip(EXCEPTIONS[(module.__name__, name)])
    sig = inspect.signature(fn)
    missing = [p for p, v in sig.parameters.items() if v.annotation is inspect.Parameter.empty]
    assert not missing, f"{module.__name__}.{name}: unannotated parameter(s) {missing}"
    assert sig.return_annotation is not inspect.Signature.empty, f"{module.__name__}.{name}: no return annotation"
    hints = typing.get_type_hints(fn)  # raises if an annotation does not resolve
    problems = {k: p for k, tp in hints.items() if (p := _problems(tp))}
    assert not problems, f"{module.__name__}.{name}: {problems}"


@pytest.mark.parametrize("module, name, fn", FUNCTIONS)
def test_no_runtime_checking(module, name, fn):
    assert not hasattr(fn, "__wrapped__"), f"{module.__name__}.{name} is wrapped (a run-time type checker?)"


@pytest.mark.parametrize("record", [model.State, model.Evaluation, model.PowerBalance, contact.Kinematics,
                                    contact.ContactForces])
def test_record_fields_are_annotated(record):
    hints = typing.get_type_hints(record)
    arrays = {k: tp for k, tp in hints.items() if tp not in ALLOWED_TYPES and tp is not dict}  # dict: State.extra
    assert arrays, record
    not_arrays = [k for k, tp in arrays.items() if not _is_array_type(tp)]
    assert not not_arrays, f"{record.__name__}: fields {not_arrays} lack a jaxtyping shape"
    problems = {k: p for k, tp in arrays.items() if (p := _problems(tp))}
    assert not problems, f"{record.__name__}: {problems}"


def test_the_check_rejects_untyped_arrays():
    assert _problems(typing.Any) and _problems(object)
    assert _problems(jaxtyping.Array)  # a bare array: no dtype, no shape
    assert _problems(jaxtyping.Float[jaxtyping.Array, " 2 M *b"])  # unknown dimension name
    assert not _problems(jaxtyping.Float[jaxtyping.Array, " 2 N *b"])
