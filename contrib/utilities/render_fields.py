# SPDX-License-Identifier: LGPL-2.1-or-later
"""Renders the last output of a run with ParaView, as a user opens it: the mesh series
(solution.xdmf, or solution.pvd) without its converted cells (threshold converted < 0.5: their
nodes no longer carry the material; XDMF only, see below), cut in half at a plane through the centre and coloured by
a field, and the particle series (particles.xdmf or particles.pvd) as points in the same colours.

    xvfb-run -a pvbatch contrib/utilities/render_fields.py RUN_DIR OUT.png [FIELD [NORMAL]]

FIELD (default von_mises_stress) must exist in both series; NORMAL is the axis x, y or z of the
cut (default x: the half x > centre is removed and the camera looks at the cut face, z up).
Needs Debian's paraview and python3-paraview (pvbatch) and xvfb.
doc/manual/output.md embeds the result.
"""
import os
import sys
import xml.etree.ElementTree as ET

from paraview.simple import (Clip, ColorBy, Threshold, GetActiveViewOrCreate, GetColorTransferFunction,
                             OpenDataFile, Render, SaveScreenshot, Show)

run, png = sys.argv[1], sys.argv[2]
field = sys.argv[3] if len(sys.argv) > 3 else "von_mises_stress"
axis = sys.argv[4] if len(sys.argv) > 4 else "x"
normal = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[axis]


def series(stem):
    for ext in (".xdmf", ".pvd"):
        path = os.path.join(run, stem + ext)
        if os.path.exists(path):
            return path
    return None


view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [1400, 1000]
view.OrientationAxesVisibility = 1
if series("solution").endswith(".pvd"):
    # solution.pvd holds the mesh (part 0) and the particles (part 1) as one multiblock; ParaView
    # 5.11's Threshold crashes on the particle block, which has no cell field 'converted'. So the
    # mesh is read from its last .pvtu directly.
    last = [d for d in ET.parse(series("solution")).getroot().iter("DataSet") if d.get("part") == "0"][-1]
    mesh = OpenDataFile(os.path.join(run, last.get("file")))
    view.ViewTime = float(last.get("timestep"))
else:
    mesh = OpenDataFile(series("solution"))
    mesh.UpdatePipelineInformation()
    times = mesh.TimestepValues
    view.ViewTime = times[-1] if times else 0.0
mesh.UpdatePipeline(view.ViewTime)
bounds = mesh.GetDataInformation().GetBounds()
centre = [(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2, (bounds[4] + bounds[5]) / 2]
# The HDF5 output stores cell fields per cell (Center="Cell"); deal.II's .vtu files store them
# as point fields of each cell's own 8 points.
association = "CELLS" if series("solution").endswith(".xdmf") else "POINTS"
kept = mesh
if series("solution").endswith(".xdmf"):
    # pvbatch 5.11 crashes (SIGSEGV in vtkExtractCells) thresholding deal.II's .pvtu once a
    # render view exists; the same threshold on the XDMF series works. VTU: converted cells shown.
    kept = Threshold(Input=mesh)
    kept.Scalars = [association, "converted"]
    kept.LowerThreshold = 0.0
    kept.UpperThreshold = 0.5
clip = Clip(Input=kept)
clip.ClipType = "Plane"
clip.ClipType.Origin = centre
clip.ClipType.Normal = normal
shown = Show(clip, view)
ColorBy(shown, ("POINTS" if field in ("displacement", "velocity") else association, field))
lut = GetColorTransferFunction(field)
particle_path = series("particles")
if particle_path:
    particles = OpenDataFile(particle_path)
    pclip = Clip(Input=particles)
    pclip.ClipType = "Plane"
    pclip.ClipType.Origin = centre
    pclip.ClipType.Normal = normal
    points = Show(pclip, view)
    points.SetRepresentationType("Points")
    points.PointSize = 4
    ColorBy(points, ("POINTS", field))
shown.SetScalarBarVisibility(view, True)
lut.RescaleTransferFunction(0.0, 5e8 if field == "von_mises_stress" else 1.0)
size = max(bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4])
k = "xyz".index(axis)
up = [0, 0, 1] if axis != "z" else [0, 1, 0]
view.CameraFocalPoint = centre
view.CameraPosition = [centre[i] + (2.5 * size if i == k else 0.6 * size * up[i]) for i in range(3)]
view.CameraViewUp = up
view.ResetCamera()
Render(view)
SaveScreenshot(png, view, ImageResolution=[1400, 1000])
print(f"{png}: t = {view.ViewTime:g} s, {os.path.basename(series('solution'))}"
      + (f" + {os.path.basename(particle_path)}" if particle_path else ""))
