"""Dynamic load balancing of the ``cpu`` backend's parallel loops: row tasks taken atomically.

Numba hands each thread one contiguous block of a ``prange``, so a frame whose top rows are sky
gives one thread less work than the other, and a thread that shares its core with another
process holds the whole stage up. The stages therefore run one ``prange`` iteration per thread,
and each thread takes the next task of ``TASK_ROWS`` consecutive rows from a shared counter
(:func:`take`) until none is left: the threads walk down the image side by side (their tap rows
overlap in the shared cache) and finish within one task of each other. No result depends on
which thread takes which task (every row is computed on its own).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

#: rows per task (720 rows: 180 tasks)
TASK_ROWS = 4


@intrinsic
def take(typingctx, counter):
    """Atomically add 1 to ``counter[0]`` (int64 array) and return its previous value.

    Numba does not know that this writes ``counter``: read ``counter[0]`` only through
    :func:`take`.
    """
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.atomic_rmw("add", array.data, ir.Constant(ir.IntType(64), 1), "monotonic")

    return types.int64(counter), codegen
