"""Compiled copies of one template function, each with its own callee: the loop (a row-wise
wrapper, a chunked reduction) is written once and numba compiles a direct call to each copy's
kernel.

A copy is the template's code object under new globals and a new ``__qualname__``
(:func:`jit_copy`), not a closure and not a kernel passed as an argument: numba keys the cache
entry of a closure on its pickled cells and that of a function-typed argument on the
dispatcher, and a pickled dispatcher carries an id drawn anew in every process, so either would
compile again (and grow its cache) in every process. numba names a cache file after the
function's module and ``__qualname__``, so every copy is cached in a file of its own (the index
keys of the copies are alike: the same bytecode). The cache of a copy follows the template's
source file (numba's stamp); the kernels it binds are callees, which numba's cache does not
track (docs/architecture.md, "numba's on-disk cache during development").
"""

from __future__ import annotations

import types

from numba import njit

__all__ = ["jit_copy"]

_MADE: dict[tuple[str, str], tuple] = {}


def jit_copy(template, name, doc, jit_options, **bound):
    """``njit(**jit_options)`` of a copy of ``template`` named ``name`` (its ``__qualname__``,
    unique per module) with docstring ``doc`` whose globals are the template module's, plus
    ``bound`` (the names the template leaves to its copies, e.g. the kernel it calls)."""
    module = template.__globals__["__name__"]
    what = (template.__name__,) + tuple(sorted((k, getattr(v, "__name__", repr(v)))
                                               for k, v in bound.items()))
    if _MADE.setdefault((module, name), what) != what:
        raise ValueError(f"jit_copy: {module}.{name} already names another copy (its cache "
                         "file is named by it)")
    g = dict(template.__globals__)
    g.update(bound)
    fn = types.FunctionType(template.__code__, g, name, template.__defaults__)
    fn.__kwdefaults__ = template.__kwdefaults__
    fn.__qualname__ = name
    fn.__doc__ = doc
    return njit(**jit_options)(fn)
