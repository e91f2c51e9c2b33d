"""Array views without a reference count, for the scene tables that called kernels read.

A Numba function that takes an array increments the array's reference count on entry and
decrements it on return (an atomic instruction each, on the one cache line that every thread's
calls share), unless Numba can prove the pair redundant, which it cannot in a function that
calls other compiled functions. The BSDF evaluation and sampling are called (not inlined) once
or twice per path vertex with the material tables, so on two threads these atomics contend for
the tables' counters. A view from :func:`borrowed` has no owner (a null meminfo): Numba's
increments and decrements test for null and do nothing.

A borrowed view must not outlive the array it was made from: use it only inside the kernel that
received that array (never return or store it).
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic


@intrinsic
def borrowed(typingctx, arr):
    """A view of ``arr`` (same data, shape and strides) that is not reference counted."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        src = context.make_array(signature.args[0])(context, builder, args[0])
        out = context.make_array(signature.return_type)(context, builder)
        context.populate_array(out, data=src.data, shape=src.shape, strides=src.strides,
                               itemsize=src.itemsize, meminfo=None, parent=None)
        return out._getvalue()

    return arr(arr), codegen
