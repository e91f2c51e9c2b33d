"""Bounding-volume hierarchy over triangles, built top-down with the binned surface-area heuristic.

Layout (structure of arrays, one row per node): ``bounds`` (N, 6) float32 holds
``(min x, min y, min z, max x, max y, max z)``, rounded outwards so that the float32 box encloses
the exact one; ``child`` (N,) int32 is the index of the left child of an interior node (the right
child is ``child + 1``) or the first triangle of a leaf; ``count`` (N,) int32 is 0 for interior
nodes and the number of triangles of a leaf. Triangles are renumbered so that each leaf covers a
contiguous range; ``order`` maps new positions to the input triangle indices. Traversal uses the
wide form of :func:`pack_wide` (8- and 4-wide nodes).

Reference: Wald, "On fast construction of SAH-based bounding volume hierarchies", RT 2007
(binned SAH); costs: traversal step 1, triangle test 1.
"""

from __future__ import annotations

import numpy as np
from numba import njit

N_BINS = 16
MAX_LEAF = 8


@njit(cache=True, error_model="numpy")
def _area(x0, y0, z0, x1, y1, z1):
    dx = max(x1 - x0, 0.0)
    dy = max(y1 - y0, 0.0)
    dz = max(z1 - z0, 0.0)
    return dx * dy + dy * dz + dz * dx


@njit(cache=True, error_model="numpy")
def _round_out(lo, hi):
    """Float32 values that enclose [lo, hi] given in float64."""
    a = np.float32(lo)
    b = np.float32(hi)
    if np.float64(a) > lo:
        a = np.nextafter(a, np.float32(-np.inf))
    if np.float64(b) < hi:
        b = np.nextafter(b, np.float32(np.inf))
    return a, b


@njit(cache=True, error_model="numpy")
def build_bvh(vertices, leaf_size=2):
    """Build the hierarchy of a triangle soup.

    Parameters
    ----------
    vertices : ndarray (T, 3, 3) float32
        Corner positions of each triangle; T >= 1.
    leaf_size : int
        Ranges of at most this many triangles become leaves without an SAH test.

    Returns
    -------
    bounds : ndarray (N, 6) float32
    child : ndarray (N,) int32
    count : ndarray (N,) int32
    order : ndarray (T,) int64
        ``order[k]`` is the input index of the triangle at position ``k``.
    depth : int
        Number of levels (the traversal stack needs at most this many entries).
    """
    n_tri = vertices.shape[0]
    lo = np.empty((n_tri, 3))
    hi = np.empty((n_tri, 3))
    cen = np.empty((n_tri, 3))
    for i in range(n_tri):
        for a in range(3):
            x0 = np.float64(vertices[i, 0, a])
            x1 = np.float64(vertices[i, 1, a])
            x2 = np.float64(vertices[i, 2, a])
            lo[i, a] = min(x0, x1, x2)
            hi[i, a] = max(x0, x1, x2)
            cen[i, a] = 0.5 * (lo[i, a] + hi[i, a])
    order = np.arange(n_tri)
    max_nodes = 2 * n_tri
    bounds = np.empty((max_nodes, 6), np.float32)
    child = np.zeros(max_nodes, np.int32)
    count = np.zeros(max_nodes, np.int32)
    stack = np.empty((n_tri + 2, 4), np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, n_tri, 1
    sp = 1
    n_nodes = 1
    max_depth = 1
    bin_cnt = np.zeros(N_BINS, np.int64)
    bin_box = np.empty((N_BINS, 6))
    right_area = np.empty(N_BINS)
    right_cnt = np.empty(N_BINS, np.int64)
    while sp > 0:
        sp -= 1
        node, start, end, depth = stack[sp, 0], stack[sp, 1], stack[sp, 2], stack[sp, 3]
        max_depth = max(max_depth, depth)
        bmin = np.full(3, np.inf)
        bmax = np.full(3, -np.inf)
        cmin = np.full(3, np.inf)
        cmax = np.full(3, -np.inf)
        for k in range(start, end):
            t = order[k]
            for a in range(3):
                bmin[a] = min(bmin[a], lo[t, a])
                bmax[a] = max(bmax[a], hi[t, a])
                cmin[a] = min(cmin[a], cen[t, a])
                cmax[a] = max(cmax[a], cen[t, a])
        for a in range(3):
            bounds[node, a], bounds[node, 3 + a] = _round_out(bmin[a], bmax[a])
        n = end - start
        if n <= leaf_size:
            child[node] = start
            count[node] = n
            continue
        parent_area = _area(bmin[0], bmin[1], bmin[2], bmax[0], bmax[1], bmax[2])
        best_cost = np.inf
        best_axis = -1
        best_bin = 0
        for a in range(3):
            extent = cmax[a] - cmin[a]
            if extent <= 0.0:
                continue
            scale = N_BINS / extent
            bin_cnt[:] = 0
            for b in range(N_BINS):
                bin_box[b, 0:3] = np.inf
                bin_box[b, 3:6] = -np.inf
            for k in range(start, end):
                t = order[k]
                b = min(int((cen[t, a] - cmin[a]) * scale), N_BINS - 1)
                bin_cnt[b] += 1
                for c in range(3):
                    bin_box[b, c] = min(bin_box[b, c], lo[t, c])
                    bin_box[b, 3 + c] = max(bin_box[b, 3 + c], hi[t, c])
            # sweep from the right: area and count of bins b..N-1
            rx0 = ry0 = rz0 = np.inf
            rx1 = ry1 = rz1 = -np.inf
            rc = 0
            for b in range(N_BINS - 1, 0, -1):
                rx0 = min(rx0, bin_box[b, 0])
                ry0 = min(ry0, bin_box[b, 1])
                rz0 = min(rz0, bin_box[b, 2])
                rx1 = max(rx1, bin_box[b, 3])
                ry1 = max(ry1, bin_box[b, 4])
                rz1 = max(rz1, bin_box[b, 5])
                rc += bin_cnt[b]
                right_area[b] = _area(rx0, ry0, rz0, rx1, ry1, rz1) if rc > 0 else 0.0
                right_cnt[b] = rc
            lx0 = ly0 = lz0 = np.inf
            lx1 = ly1 = lz1 = -np.inf
            lc = 0
            for b in range(N_BINS - 1):
                lx0 = min(lx0, bin_box[b, 0])
                ly0 = min(ly0, bin_box[b, 1])
                lz0 = min(lz0, bin_box[b, 2])
                lx1 = max(lx1, bin_box[b, 3])
                ly1 = max(ly1, bin_box[b, 4])
                lz1 = max(lz1, bin_box[b, 5])
                lc += bin_cnt[b]
                if lc == 0 or right_cnt[b + 1] == 0:
                    continue
                left_area = _area(lx0, ly0, lz0, lx1, ly1, lz1)
                cost = 1.0 + (left_area * lc + right_area[b + 1] * right_cnt[b + 1]) / max(parent_area, 1e-300)
                if cost < best_cost:
                    best_cost = cost
                    best_axis = a
                    best_bin = b
        degenerate = best_axis < 0 and n <= 4 * MAX_LEAF
        if degenerate or (best_cost >= n and n <= MAX_LEAF):
            child[node] = start
            count[node] = n
            continue
        mid = start
        if best_axis >= 0:
            a = best_axis
            scale = N_BINS / (cmax[a] - cmin[a])
            i, j = start, end - 1
            while i <= j:
                b = min(int((cen[order[i], a] - cmin[a]) * scale), N_BINS - 1)
                if b <= best_bin:
                    i += 1
                else:
                    order[i], order[j] = order[j], order[i]
                    j -= 1
            mid = i
        if mid == start or mid == end:
            mid = (start + end) // 2
        left = n_nodes
        n_nodes += 2
        child[node] = left
        count[node] = 0
        stack[sp, 0], stack[sp, 1], stack[sp, 2], stack[sp, 3] = left + 1, mid, end, depth + 1
        sp += 1
        stack[sp, 0], stack[sp, 1], stack[sp, 2], stack[sp, 3] = left, start, mid, depth + 1
        sp += 1
    return bounds[:n_nodes].copy(), child[:n_nodes].copy(), count[:n_nodes].copy(), order, max_depth


LEAF_BITS = 6  # a leaf code holds the triangle count in its low bits (count < 64)
WIDTH = 8  # children per wide node (the lanes of :func:`.simd.box8`)
NARROW = 4  # children per narrow node (the lanes of :func:`.simd.box4`)
ROW = 64  # float32 / int32 columns of an 8-wide node: 6 planes x 8 lanes, 8 child codes, 8 unused
UNIT = 32  # float32 / int32 columns per storage unit (128 bytes): a narrow node, or half a wide one
ROOT = 1  # the code of the root: an 8-wide node at unit 0


@njit(cache=True, error_model="numpy")
def _box_area(bounds, n):
    """Half the surface area of node ``n``'s box (float64 of the float32 bounds)."""
    dx = np.float64(bounds[n, 3]) - bounds[n, 0]
    dy = np.float64(bounds[n, 4]) - bounds[n, 1]
    dz = np.float64(bounds[n, 5]) - bounds[n, 2]
    return dx * dy + dy * dz + dz * dx


@njit(cache=True, error_model="numpy")
def _collapse(bounds, child, count, rows_f, rows_i):
    """Fill wide rows from the binary tree; returns the number of rows used."""
    n_rows = 1
    work = np.empty(len(bounds) + 1, np.int64)  # (binary node, row) pairs waiting to be filled
    work_row = np.empty(len(bounds) + 1, np.int64)
    cand = np.empty(WIDTH, np.int64)
    cand_area = np.empty(WIDTH)
    work[0] = 0
    work_row[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        b = work[sp]
        row = work_row[sp]
        if count[b] > 0:  # a leaf root: one lane
            cand[0] = b
            m = 1
        else:
            cand[0] = child[b]
            cand[1] = child[b] + 1
            m = 2
            # open the interior candidate of largest surface area until the node is full
            while m < WIDTH:
                best = -1
                best_area = -1.0
                for k in range(m):
                    c = cand[k]
                    if count[c] == 0:
                        area = _box_area(bounds, c)
                        if area > best_area:
                            best_area = area
                            best = k
                if best < 0:
                    break
                c = cand[best]
                cand[best] = child[c]
                cand[m] = child[c] + 1
                m += 1
        for k in range(m):
            cand_area[k] = _box_area(bounds, cand[k])
        for k in range(1, m):  # lanes by decreasing box area (stable): any-hit queries try the largest first
            c, area = cand[k], cand_area[k]
            j = k
            while j > 0 and cand_area[j - 1] < area:
                cand[j], cand_area[j] = cand[j - 1], cand_area[j - 1]
                j -= 1
            cand[j], cand_area[j] = c, area
        for k in range(m):
            c = cand[k]
            for p in range(6):
                rows_f[row, WIDTH * p + k] = bounds[c, p]
            if count[c] > 0:
                rows_i[row, 6 * WIDTH + k] = -1 - ((child[c] << LEAF_BITS) | count[c])
            else:
                rows_i[row, 6 * WIDTH + k] = n_rows
                work[sp] = c
                work_row[sp] = n_rows
                sp += 1
                n_rows += 1
    return n_rows


@njit(cache=True, error_model="numpy")
def _to_units(rows_f, rows_i, n_rows, units_i):
    """Store the wide rows as 8-wide nodes (2 units) or, with at most 4 children, 4-wide nodes (1
    unit); interior children's codes become ``unit << 1 | wide``. Returns the units used."""
    first = np.empty(n_rows, np.int64)
    wide = np.empty(n_rows, np.int64)
    u = 0
    for r in range(n_rows):
        m = 0
        for k in range(WIDTH):
            if rows_i[r, 6 * WIDTH + k] != -1:
                m += 1
        wide[r] = 1 if (r == 0 or m > NARROW) else 0
        first[r] = u
        u += 2 if wide[r] else 1
    units_f = units_i.view(np.float32)
    for r in range(n_rows):
        lanes = WIDTH if wide[r] else NARROW
        flat = first[r] * UNIT
        for p in range(6):
            for k in range(lanes):
                c = flat + lanes * p + k
                units_f[c // UNIT, c % UNIT] = rows_f[r, WIDTH * p + k]
        for k in range(lanes):
            code = rows_i[r, 6 * WIDTH + k]
            if code >= 0:
                code = (first[code] << 1) | wide[code]
            c = flat + 6 * lanes + k
            units_i[c // UNIT, c % UNIT] = code
    return u


def pack_wide(bounds: np.ndarray, child: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The binary tree collapsed into a wide one of 8- and 4-wide nodes, cache-line aligned.

    Each wide node takes the children of a binary node and repeatedly replaces the interior one
    of largest surface area by its two children, until it has 8 children or only leaves (the
    usual collapse of a binary SAH tree). Its children are stored by decreasing box area: an
    any-hit query visits the lowest lane it hits first, and a large box is the likeliest to hold
    an occluder (classroom shadow rays: 5.4 -> 6.9 M per CPU-second, ``docs/pathtracer.md``);
    closest-hit queries order the children by distance anyway. A node with at most 4 children (about half of them on
    the classroom, where nodes average 4.2 children) is stored 4 wide, in one 128-byte unit (two
    cache lines); the others, and the root, 8 wide in two units (four lines), so that traversal
    reads half the memory for a narrow node. An 8-wide node from column ``c = 32 * unit``: columns
    ``c + 8 * p + k`` (float32) are plane ``p`` (min x, min y, min z, max x, max y, max z) of child
    ``k``, so that each plane of all 8 children is one vector load (:func:`.simd.box8`), and
    columns ``c + 48 + k`` (int32 view) are the children's codes. A 4-wide node: planes at ``c + 4 *
    p + k`` (:func:`.simd.box4`), codes at ``c + 24 + k``. A code is ``unit << 1 | wide`` for an
    interior child (``wide`` = 1 for an 8-wide node), or ``-1 - (first << LEAF_BITS | count)`` for
    a leaf of ``count`` triangles from ``first``. Unused lanes hold an empty box (min +inf, max
    -inf, never entered) and the code of an empty leaf (-1). The root is 8 wide at unit 0 (code
    :data:`ROOT`); a tree that is a single leaf gets a root with that leaf as its only child.

    Returns
    -------
    nodes_f : ndarray (U, 32) float32
    nodes_i : ndarray (U, 32) int32
        Two views of the same 64-byte-aligned memory.
    """
    n = len(bounds)
    if len(count) and (int(count.max()) >= 1 << LEAF_BITS or int(child.max()) >= (1 << (31 - LEAF_BITS)) - 1):
        raise ValueError("BVH too large for the packed node codes")
    work_i = np.zeros((n, ROW), np.int32)  # enough rows: each but the root is an interior binary node
    work_f = work_i.view(np.float32)
    work_f[:, :3 * WIDTH] = np.inf
    work_f[:, 3 * WIDTH:6 * WIDTH] = -np.inf
    work_i[:, 6 * WIDTH:7 * WIDTH] = -1  # unused lanes: an empty leaf
    rows = _collapse(bounds, child, count, work_f, work_i)
    units_i = np.zeros((2 * rows, UNIT), np.int32)
    units = _to_units(work_f, work_i, rows, units_i)
    buf = np.empty(units * UNIT + 16, np.int32)
    start = (-buf.ctypes.data % 64) // 4
    nodes_i = buf[start:start + units * UNIT].reshape(units, UNIT)
    nodes_i[:] = units_i[:units]
    return nodes_i.view(np.float32), nodes_i
