"""Stand-ins for guide channels a capture lacks: what a filter's degraded mode reads instead.

Captured frames often hold colour, albedo and normal only (what an OIDN user has). A filter that
can run on fewer guides declares the others ``optional`` (:class:`harness.FilterSpec`) and fills
what is missing with these stand-ins; the row's ``guides`` column then names the guides it had.
(A missing ``variance`` is the filter's own business: SBF and LBF estimate it from the image.)

* :func:`pinhole_position`: a camera-space position from depth (or unit depth) and the pixel's
  place, for an unknown camera of a 53 degree horizontal field of view: differences between
  neighbours are right in proportion, not in scene units.
* :func:`constant_depth`, :func:`zero_motion`, :func:`one_object`: neutral values (every
  depth stop passes, no motion, one object).
* :func:`camera_motion` (:func:`static_motion` on arrays): the motion vectors of static
  geometry, from ``position`` or ``depth`` and the frame's ``view_proj`` and
  ``prev_view_proj``, for captures without ``motion`` whose camera is known; objects that move
  get the motion of the camera alone. :func:`camera_motion_ready` says whether a sequence's
  frames allow it; a row's ``guides`` column names it :data:`CAMERA_MOTION`.
"""

from __future__ import annotations

import numpy as np


def pinhole_position(shape, depth: np.ndarray | None = None) -> np.ndarray:
    """Camera-space positions (H, W, 3) float32 of an unknown pinhole camera (53 degree horizontal
    field of view) from ``depth`` (H, W), or at depth 1 where None; non-finite depth counts as 1."""
    h, w = shape
    z = np.ones((h, w)) if depth is None else np.asarray(depth, np.float64)
    z = np.where(np.isfinite(z), z, 1.0)
    x = (np.arange(w) + 0.5 - 0.5 * w) / w
    y = (np.arange(h) + 0.5 - 0.5 * h) / w
    return np.stack([x[None, :] * z, y[:, None] * z, z], axis=-1).astype(np.float32)


def constant_depth(shape) -> np.ndarray:
    """Depth 1 at every pixel (H, W) float32: depth edge stops pass everywhere."""
    return np.ones(shape, np.float32)


def zero_motion(shape) -> np.ndarray:
    """No motion (H, W, 2) float32."""
    return np.zeros((*shape, 2), np.float32)


def one_object(shape) -> np.ndarray:
    """Object id 0 at every pixel (H, W) int32."""
    return np.zeros(shape, np.int32)


#: the name of camera-derived motion in a row's ``guides`` column (:meth:`harness.FilterSpec.guides_used`)
CAMERA_MOTION = "motion(camera)"


def _camera_rows(view_proj):
    """The x, y and w rows of a world-to-clip matrix, split into their (3, 3) spatial part and
    translation, and that part's inverse; None where the matrix is missing, not a finite 4x4,
    or not a perspective projection (its x, y, w rows do not determine a point)."""
    if view_proj is None:
        return None
    m = np.asarray(view_proj, np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        return None
    rows = m[[0, 1, 3], :3]
    scale = float(np.abs(rows).max())
    if not np.linalg.norm(rows[2]) > 1e-12 * scale or np.linalg.cond(rows) > 1e12:
        return None
    inverse = np.linalg.inv(rows)
    return rows, m[[0, 1, 3], 3], inverse


def static_motion(view_proj, prev_view_proj, *, depth=None, position=None, background=None,
                  jitter=(0.0, 0.0), prev_jitter=(0.0, 0.0)) -> np.ndarray | None:
    """Motion vectors (H, W, 2) float32 of static geometry from the camera matrices alone.

    The convention of :mod:`harness.buffers` and :meth:`harness.Scene.motion`: ``motion[i, j] =
    (dx, dy)`` says that the surface seen at pixel (i, j) was at image coordinates ``(j + dx, i +
    dy)`` of the previous frame's unjittered image (pixel centres on integers, y down); a
    background pixel follows the direction through its unjittered pixel centre, infinitely far.
    Where the scene's objects do not move this equals the renderer's ``motion`` channel.

    Parameters
    ----------
    view_proj, prev_view_proj : array_like (4, 4) or None
        World-to-clip matrices (OpenGL) of this and the previous frame, each including its
        frame's jitter (:attr:`harness.FrameMeta.view_proj`).
    depth : ndarray (H, W), optional
        View-space z (positive, :mod:`harness.buffers`); ``+inf`` marks background. Each point is
        unprojected from its pixel centre through ``view_proj``.
    position : ndarray (H, W, 3), optional
        World positions of the first hits; used instead of ``depth`` when given.
    background : ndarray (H, W) bool, optional
        Background pixels (with ``position``; with ``depth`` ``+inf`` marks them as well).
    jitter, prev_jitter : (float, float)
        The jitter in ``view_proj`` and in ``prev_view_proj`` (:attr:`harness.FrameMeta.jitter`
        of this and the previous frame), pixels, x right, y down.

    Returns
    -------
    ndarray (H, W, 2) float32 or None
        None where a matrix is missing, not finite or not a perspective projection, or neither
        ``depth`` nor ``position`` is given. Pixels with no previous position (behind the
        previous camera, in its eye plane, non-finite or non-positive depth, non-finite
        position) are sent to image coordinates ``(-(W + H), -(W + H))`` of the previous frame,
        outside it by more than the image's size, so reprojection finds no history there
        (:meth:`harness.Scene.motion` gives them zero motion instead). Previous positions
        farther than ``W + H`` outside the image are moved to that distance (still outside), so
        every value is finite.

    Notes
    -----
    ``depth`` is unprojected through the inverse of the x, y and w rows of ``view_proj`` (its z
    row plays no part), taking the clip-space w of a point as its depth times the length of
    the w row's spatial part: right for a rigid view and a pinhole projection, as the harness's
    renderers and OpenGL or Direct3D matrices have. Arithmetic in float64.
    """
    cur, prev = _camera_rows(view_proj), _camera_rows(prev_view_proj)
    if cur is None or prev is None or (depth is None and position is None):
        return None
    rows, shift, inverse = cur
    prows, pshift, _ = prev
    # clip (x, y, w) of this frame -> the previous frame's: prows @ inverse @ (clip - shift) + pshift
    fold = prows @ inverse
    if position is not None:
        pts = np.asarray(position)
        h, w = pts.shape[:2]
    else:
        z = np.asarray(depth, np.float64)
        h, w = z.shape
    jj = np.arange(w, dtype=np.float64)
    ii = np.arange(h, dtype=np.float64)[:, None]
    with np.errstate(all="ignore"):
        if position is None:
            # this frame's clip (x, y, w) = (nx w, ny w, w) with w = s z, s the length of the w
            # row's spatial part; nx, ny: the pixel centre (the jittered sample) in NDC
            wc = np.linalg.norm(rows[2]) * z
            nx = 2.0 * (jj + 0.5) / w - 1.0
            ny = 1.0 - 2.0 * (ii + 0.5) / h
            const = pshift - fold @ shift
            px, py, pw = (wc * (fold[k, 0] * nx + fold[k, 1] * ny + fold[k, 2]) + const[k] for k in range(3))
            ok = np.isfinite(z) & (z > 0.0)
            sky = z == np.inf
        else:
            x0, x1, x2 = (np.asarray(pts[..., k], np.float64) for k in range(3))
            px, py, pw = (prows[k, 0] * x0 + prows[k, 1] * x1 + prows[k, 2] * x2 + pshift[k] for k in range(3))
            ok = np.isfinite(x0) & np.isfinite(x1) & np.isfinite(x2)
            sky = np.zeros((h, w), bool)
        if background is not None:
            sky = sky | np.asarray(background, bool)
        if sky.any():
            # the direction through the unjittered pixel centre, a point at infinity (w = 0)
            si, sj = np.nonzero(sky)
            nx = 2.0 * (sj - jitter[0] + 0.5) / w - 1.0
            ny = 1.0 - 2.0 * (si - jitter[1] + 0.5) / h
            for k, out in enumerate((px, py, pw)):
                out[sky] = fold[k, 0] * nx + fold[k, 1] * ny + fold[k, 2]
            ok = ok | sky
        x = (px / pw + 1.0) * 0.5 * w - 0.5 + prev_jitter[0]
        y = (1.0 - py / pw) * 0.5 * h - 0.5 + prev_jitter[1]
        ok &= (pw > 0.0) & np.isfinite(x) & np.isfinite(y)
    margin = w + h
    motion = np.empty((h, w, 2), np.float32)
    motion[..., 0] = np.where(ok, np.clip(x, -margin, w - 1 + margin), -margin) - jj
    motion[..., 1] = np.where(ok, np.clip(y, -margin, h - 1 + margin), -margin) - ii
    return motion


def camera_motion(frame, prev_jitter=(0.0, 0.0)) -> np.ndarray | None:
    """Motion (H, W, 2) float32 of a :class:`harness.Frame`'s static geometry, from its
    ``position`` (or else its ``depth``) and its metadata's matrices (:func:`static_motion`).

    Background is where ``depth`` is ``+inf``, or else ``object_id`` is negative, or else (with
    ``position`` alone) the position is exactly zero (the harness's background value). None
    where :func:`static_motion` gives None. ``prev_jitter`` is the previous frame's
    :attr:`harness.FrameMeta.jitter` (the jitter in ``frame.meta.prev_view_proj``).
    """
    meta = frame.meta
    depth, position = frame.get("depth"), frame.get("position")
    background = None
    if position is not None:
        if depth is not None:
            background = depth == np.inf
        elif "object_id" in frame:
            background = frame["object_id"] < 0
        else:
            background = ~position.any(axis=-1)
        depth = None
    return static_motion(meta.view_proj, meta.prev_view_proj, depth=depth, position=position,
                         background=background, jitter=meta.jitter, prev_jitter=prev_jitter)


def camera_motion_ready(channels, metas) -> bool:
    """True if frames with ``channels`` and metadata ``metas`` (one :class:`harness.FrameMeta`
    per frame of a sequence) give :func:`camera_motion` on every frame that may use history:
    ``depth`` or ``position`` among the channels, at least one frame that is not a camera cut,
    and perspective ``view_proj`` and ``prev_view_proj`` on each of those."""
    if not {"depth", "position"} & set(channels):
        return False
    later = [m for m in metas if not m.camera_cut]
    return bool(later) and all(_camera_rows(m.view_proj) is not None and _camera_rows(m.prev_view_proj) is not None
                               for m in later)
