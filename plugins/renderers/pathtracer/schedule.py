"""Dynamic load balancing of the parallel kernels: a shared task counter, taken atomically.

Numba's threading layers hand each thread one contiguous block of a ``prange`` (even under
``numba.parallel_chunksize``), so an image split into row-major tasks gives one thread the top
and the other the bottom, whatever their cost, and a thread that shares its core with another
process holds the frame up. The kernels therefore run one ``prange`` iteration per thread, and
each thread takes the next task from :func:`take` until none is left: the threads walk through
the image together, in task order, and finish within one task of each other. Which thread takes
which task does not affect any result (every pixel is computed on its own).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def take(typingctx, counter):
    """Atomically increment ``counter[0]`` (int64 array) and return its previous value.

    Numba does not know that this writes ``counter``: in the function that owns the counter,
    ``counter[0]`` read after the parallel loop may give the value from before it.
    """
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.atomic_rmw("add", ary.data, ir.Constant(ir.IntType(64), 1), "monotonic")

    return types.int64(counter), codegen
