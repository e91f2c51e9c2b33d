"""SIMD building blocks of BVH traversal, written as Numba intrinsics in LLVM IR.

:func:`box8` tests a ray against the eight child boxes of one wide BVH node with packed
single-precision vector operations (one <8 x float> per plane, 256-bit registers on x86), which
Numba's auto-vectoriser does not produce from scalar code; :func:`box4` does the same for the
four boxes of a narrow node (<4 x float>, the same arithmetic lane for lane). :func:`lowest_bit`
is the count-trailing-zeros instruction, for walking the hit mask they return; :func:`prefetch`
asks for the rows of children that traversal will visit later.

Node layout (see :func:`.bvh.pack_wide`): units of 32 float32 / int32 (128 bytes); an 8-wide node
spans two units from ``c = 32 * unit``, with plane ``p`` of child ``k`` at ``c + 8 * p + k`` (planes
in the order min x, min y, min z, max x, max y, max z) and the children's codes at ``c + 48 + k``;
a 4-wide node is one unit, planes at ``c + 4 * p + k``, codes at ``c + 24 + k``.

Conservative single precision (Ize, "Robust BVH ray traversal", JCGT 2013): the ray constants of
:func:`.traverse.ray_setup` are float32 values rounded so that every slab distance is at worst
moved outwards (the origin rounded away from the plane by 1.5-4.5 float32 ulps), the inverse
direction is rounded to nearest, and the far distance is widened by ``1 + 2**-20`` (more than
``(1 + gamma_3) / (1 - gamma_3)``, ``gamma_3 = 3u / (1 - 3u)``, ``u = 2**-24``), so that a box the
ray meets within ``[0, tmax]`` in exact arithmetic is always reported (a box just missed may be
reported too). A zero direction component has an infinite inverse; the origin shift keeps
``0 * inf`` away from boxes that contain the origin's coordinate, and the NaN it can still give for
a plane beyond the origin is ignored by the min/max (``select(a > b, a, b)``, with the new term as
``a``), so that slab then does not reject the box.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .bvh import UNIT
from .bvh import WIDTH as LANES

FAR_SCALE = 1.0 + 2.0**-20  # widening of the exit distance


def _vec_load(builder, base_ptr, index, lanes):
    """Load <lanes x float> from ``base_ptr[index]`` (element pointer, any alignment)."""
    vty = ir.VectorType(ir.FloatType(), lanes)
    ptr = builder.gep(base_ptr, [index])
    return builder.load(builder.bitcast(ptr, vty.as_pointer()), align=4)


def _splat(builder, value, lanes):
    vty = ir.VectorType(ir.FloatType(), lanes)
    one = builder.insert_element(ir.Constant(vty, ir.Undefined), value, ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(one, ir.Constant(vty, ir.Undefined), ir.Constant(ir.VectorType(ir.IntType(32), lanes),
                                                                               [0] * lanes))


def _vmax(builder, new, acc):
    """max with a NaN ``new`` lane ignored (``select(new > acc, new, acc)``)."""
    return builder.select(builder.fcmp_ordered(">", new, acc), new, acc)


def _vmin(builder, new, acc):
    """min with a NaN ``new`` lane ignored (``select(new < acc, new, acc)``)."""
    return builder.select(builder.fcmp_ordered("<", new, acc), new, acc)


def _box_codegen(lanes):
    """Code generator of the ``lanes``-wide box test (8: :func:`box8`, 4: :func:`box4`)."""
    far_base = tuple(3 * lanes + 2 * lanes * a for a in range(3))  # far column = far_base - near column

    def codegen(context, builder, signature, args):
        a_nodes, a_unit, a_ray, a_cols, a_out, a_at = args
        i64 = ir.IntType(64)
        nodes = context.make_array(signature.args[0])(context, builder, a_nodes)
        out = context.make_array(signature.args[4])(context, builder, a_out)
        unit64 = context.cast(builder, a_unit, signature.args[1], types.int64)
        base = builder.mul(unit64, ir.Constant(i64, UNIT))
        vals = [builder.extract_value(a_ray, k) for k in range(10)]
        tmax = vals[9]
        offs = [builder.extract_value(a_cols, a) for a in range(3)]
        if lanes != LANES:  # the columns of :func:`.traverse.ray_setup` are for 8 lanes
            offs = [builder.udiv(o, ir.Constant(i64, LANES // lanes)) for o in offs]
        near = _splat(builder, ir.Constant(ir.FloatType(), 0.0), lanes)
        far = _splat(builder, tmax, lanes)
        for a in range(3):
            on = _splat(builder, vals[a], lanes)
            of = _splat(builder, vals[3 + a], lanes)
            inv = _splat(builder, vals[6 + a], lanes)
            col_n = builder.add(base, offs[a])
            col_f = builder.add(base, builder.sub(ir.Constant(i64, far_base[a]), offs[a]))
            lo = _vec_load(builder, nodes.data, col_n, lanes)
            hi = _vec_load(builder, nodes.data, col_f, lanes)
            tn = builder.fmul(builder.fsub(lo, on), inv)
            tf = builder.fmul(builder.fsub(hi, of), inv)
            near = _vmax(builder, tn, near)
            far = _vmin(builder, tf, far)
        far = builder.fmul(far, _splat(builder, ir.Constant(ir.FloatType(), FAR_SCALE), lanes))
        hit = builder.fcmp_ordered("<=", near, far)
        vty = ir.VectorType(ir.FloatType(), lanes)
        at64 = context.cast(builder, a_at, signature.args[5], types.int64)
        builder.store(near, builder.bitcast(builder.gep(out.data, [at64]), vty.as_pointer()), align=4)
        bits = builder.bitcast(hit, ir.IntType(lanes))
        return builder.zext(bits, i64)

    return codegen


def _box_signature(nodes_f, unit, ray, cols, near_out, at):
    ok = (isinstance(nodes_f, types.Array) and nodes_f.dtype == types.float32 and nodes_f.ndim == 2
          and nodes_f.layout == "C" and isinstance(unit, types.Integer)
          and isinstance(ray, types.UniTuple) and ray.count == 10 and ray.dtype == types.float32
          and isinstance(cols, types.UniTuple) and cols.count == 3 and cols.dtype == types.int64
          and isinstance(near_out, types.Array) and near_out.dtype == types.float32 and near_out.ndim == 1
          and near_out.layout == "C" and isinstance(at, types.Integer))
    return types.int64(nodes_f, unit, ray, cols, near_out, at) if ok else None


@intrinsic
def box8(typingctx, nodes_f, unit, ray, cols, near_out, at):
    """Hit mask of a ray against the eight child boxes of the 8-wide node at unit ``unit``.

    Parameters
    ----------
    nodes_f : ndarray (U, 32) float32, C-contiguous
        Node units (:func:`.bvh.pack_wide`); an 8-wide node spans units ``unit`` and ``unit + 1``.
    unit : int
        The node's first unit.
    ray : tuple of 10 float32
        From :func:`.traverse.ray_setup`: origin for the near planes (x, y, z), origin for the far
        planes, inverse direction, then ``tmax`` rounded up.
    cols : tuple of 3 int64
        First column of the near planes per axis in an 8-wide node (0 or 24 for x, 8 or 32 for y,
        16 or 40 for z: the min planes for a non-negative inverse direction, else the max planes).
    near_out : ndarray float32, C-contiguous
        Receives the entry distance of child ``k`` at ``near_out[at + k]`` (meaningful for the
        lanes in the mask; ``at + 8 <= len(near_out)`` is the caller's to ensure).
    at : int

    Returns
    -------
    int64
        Bit ``k`` set when child ``k``'s box is met at a distance in ``[0, tmax]``.
    """
    sig = _box_signature(nodes_f, unit, ray, cols, near_out, at)
    return None if sig is None else (sig, _box_codegen(8))


@intrinsic
def box4(typingctx, nodes_f, unit, ray, cols, near_out, at):
    """:func:`box8` for the four child boxes of the 4-wide node at unit ``unit`` (planes of 4
    lanes; ``cols`` as for :func:`box8`, halved here; 4 entry distances written)."""
    sig = _box_signature(nodes_f, unit, ray, cols, near_out, at)
    return None if sig is None else (sig, _box_codegen(4))


@intrinsic
def lowest_bit(typingctx, mask):
    """Index of the lowest set bit of a non-zero int64 (count trailing zeros)."""
    if not isinstance(mask, types.Integer):
        return None
    sig = types.int64(mask)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(i64, [i64, ir.IntType(1)]),
                                            "llvm.cttz.i64")
        value = context.cast(builder, args[0], signature.args[0], types.int64)
        return builder.call(fn, [value, ir.Constant(ir.IntType(1), 1)])

    return sig, codegen


@intrinsic
def prefetch(typingctx, arr, row, lines):
    """Ask the cache for ``lines`` (a literal int) 64-byte lines from the start of row ``row`` of a
    C-contiguous 2D array; no effect on results."""
    ok = (isinstance(arr, types.Array) and arr.ndim == 2 and arr.layout == "C" and isinstance(row, types.Integer)
          and isinstance(lines, types.IntegerLiteral))
    if not ok:
        return None
    count = lines.literal_value

    def codegen(context, builder, signature, args):
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        row64 = context.cast(builder, args[1], signature.args[1], types.int64)
        stride = cgutils.unpack_tuple(builder, ary.strides, 2)[0]
        base = builder.gep(builder.bitcast(ary.data, i8p), [builder.mul(row64, stride)])
        for k in range(count):
            ptr = builder.gep(base, [ir.Constant(ir.IntType(64), 64 * k)])
            builder.call(fn, [ptr, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return types.none(arr, row, lines), codegen
