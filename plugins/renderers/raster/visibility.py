"""Off-screen VTK rasterization of a visibility buffer: which triangle covers each pixel centre.

The index of every triangle is float32 cell data, drawn with VTK's ``vtkValuePass``, which
writes the unshaded, unquantized value of the covering cell into a float render target (exact
for indices below 2**24; point data would be interpolated, which Mesa does only to about 1e-5
relative precision). The projection is passed to VTK as an explicit matrix, so VTK samples
exactly the pixel centres (plus jitter) that :meth:`harness.CameraPath.primary_rays` uses; every
other G-buffer value is then computed in float from the ray and the triangle (see
:mod:`.attributes`).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

MAX_TRIANGLES = 1 << 24  # float32 holds every integer below this exactly


class VisibilityRasterizer:
    """A reusable off-screen VTK window that draws triangle indices, from any thread.

    An OpenGL context is current on one thread only: drawn from another thread, VTK's window
    reads back buffers of the wrong size and logs shader errors (seen when a Dask client's pool
    threads drew references one after the other). The window is therefore created and used on
    one thread of its own; :meth:`triangle_ids` hands each draw to it and waits, so callers on
    any thread, several at once included, are served one at a time.

    Notes
    -----
    Uses EGL off-screen rendering where VTK was built with it (set
    ``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, done here when unset), otherwise VTK's
    default off-screen window.
    """

    def __init__(self):
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="vtk-visibility")
        self._drawing = self._thread.submit(_VtkDrawing).result()

    def triangle_ids(self, vertices: np.ndarray, view_proj: np.ndarray, width: int, height: int) -> np.ndarray:
        """Index of the triangle seen at each pixel centre (drawn on the window's own thread).

        Parameters
        ----------
        vertices : ndarray (T, 3, 3)
            World-space triangle corners.
        view_proj : ndarray (4, 4)
            World-to-clip matrix (OpenGL convention) whose near and far planes enclose the scene.
        width, height : int

        Returns
        -------
        ndarray (height, width) int32
            Triangle index, -1 where no triangle covers the pixel centre. Row 0 is the top row.
        """
        return self._thread.submit(self._drawing.triangle_ids, vertices, view_proj, width, height).result()


class _VtkDrawing:
    """The VTK objects of :class:`VisibilityRasterizer`; built and used on its one thread."""

    def __init__(self):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        import vtk

        self._vtk = vtk
        self._mapper = vtk.vtkPolyDataMapper()
        self._mapper.SetScalarModeToUseCellFieldData()
        self._mapper.SelectColorArray("tri")
        self._mapper.ScalarVisibilityOn()
        self._actor = actor = vtk.vtkActor()
        actor.SetMapper(self._mapper)
        self._renderer = vtk.vtkRenderer()
        self._renderer.AddActor(actor)
        self._window = vtk.vtkRenderWindow()
        self._window.SetOffScreenRendering(1)
        self._window.SetMultiSamples(0)
        self._window.AddRenderer(self._renderer)
        self._value_pass = None
        self._drawn_count = 1
        # one ordinary render of a mesh carrying the "tri" array creates the GL context and the
        # mapper's state, which the value pass needs before it is installed (VTK crashes otherwise)
        self._mesh = _mesh(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32))
        self._mapper.SetInputData(self._mesh)
        self._window.SetSize(8, 8)
        self._window.Render()
        self._install_value_pass()

    def _install_value_pass(self) -> None:
        vtk = self._vtk
        value_pass = vtk.vtkValuePass()
        value_pass.SetInputArrayToProcess(vtk.VTK_SCALAR_MODE_USE_CELL_FIELD_DATA, "tri")
        value_pass.SetInputComponentToProcess(0)
        passes = vtk.vtkRenderPassCollection()
        passes.AddItem(value_pass)
        sequence = vtk.vtkSequencePass()
        sequence.SetPasses(passes)
        camera_pass = vtk.vtkCameraPass()
        camera_pass.SetDelegatePass(sequence)
        self._renderer.SetPass(camera_pass)
        self._value_pass = value_pass
        self._passes = (passes, sequence, camera_pass)  # Python wrappers live as long as the window

    def triangle_ids(self, vertices: np.ndarray, view_proj: np.ndarray, width: int, height: int) -> np.ndarray:
        """See :meth:`VisibilityRasterizer.triangle_ids`."""
        from vtk.util.numpy_support import vtk_to_numpy

        vtk = self._vtk
        count = len(vertices)
        if count >= MAX_TRIANGLES:
            raise ValueError(f"raster: {count} triangles exceed the visibility buffer's limit of {MAX_TRIANGLES}")
        if count == 0:
            return np.full((height, width), -1, np.int32)
        # VTK's value pass reads the previously drawn input during the next render (see below):
        # the previous mesh is kept alive until then
        self._previous_mesh, self._mesh = self._mesh, _mesh(vertices)
        self._mapper.SetInputData(self._mesh)
        self._window.SetSize(int(width), int(height))
        self._matrix = matrix = vtk.vtkMatrix4x4()
        for i in range(4):
            for j in range(4):
                matrix.SetElement(i, j, float(view_proj[i, j]))
        camera = self._renderer.GetActiveCamera()
        # identity view: the whole world-to-clip transform goes into the explicit projection
        camera.SetPosition(0.0, 0.0, 0.0)
        camera.SetFocalPoint(0.0, 0.0, -1.0)
        camera.SetViewUp(0.0, 1.0, 0.0)
        camera.SetExplicitProjectionTransformMatrix(matrix)
        camera.SetUseExplicitProjectionTransformMatrix(True)
        self._window.Render()
        if count != self._drawn_count:
            # vtkValuePass maps drawn primitives to cells with the mapper's input of the previous
            # render; after the input's size changed, render again with fresh data
            self._mesh.Modified()
            self._window.Render()
            self._drawn_count = count
        values = vtk_to_numpy(self._value_pass.GetFloatImageDataArray(self._renderer))
        values = values.reshape(height, width)[::-1]
        ids = np.full((height, width), -1, np.int32)
        hit = np.isfinite(values)
        ids[hit] = np.rint(values[hit]).astype(np.int32)
        ids[(ids < 0) | (ids >= count)] = -1
        return ids


def _mesh(vertices: np.ndarray):
    """Unshared-vertex triangle ``vtkPolyData`` whose corners carry their triangle's index (``tri``).

    Every array is deep-copied into VTK-owned memory, so the mesh lives as long as VTK holds it.
    """
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    count = len(vertices)
    points = vtk.vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(vertices, np.float32).reshape(-1, 3), deep=True))
    cells = vtk.vtkCellArray()
    offsets = np.arange(0, 3 * count + 1, 3, dtype=np.int64)
    connectivity = np.arange(3 * count, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True), numpy_to_vtkIdTypeArray(connectivity, deep=True))
    tri = numpy_to_vtk(np.arange(count, dtype=np.float32), deep=True)
    tri.SetName("tri")
    mesh = vtk.vtkPolyData()
    mesh.SetPoints(points)
    mesh.SetPolys(cells)
    mesh.GetCellData().AddArray(tri)
    return mesh
