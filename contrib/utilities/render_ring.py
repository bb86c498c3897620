# SPDX-License-Identifier: LGPL-2.1-or-later
"""Renders the end state of an expanding-ring run (prm/verification/fragmentation/ring.prm with
'K - Output/fields = true') with ParaView, as a user would look at it: the particles at the
last output, coloured by a point field (default intact_bonds; strength_factor shows the flaws).

    xvfb-run -a pvbatch contrib/utilities/render_ring.py RUN_DIR OUT.png [FIELD [ZOOM]]

ZOOM > 1 looks at the top of the ring (x = 0, y = R) magnified ZOOM times.

Needs Debian's paraview (pvbatch) and xvfb. doc/manual/fragmentation_ring_draft.md embeds the
result.
"""
import sys

from paraview.simple import (ColorBy, GetActiveViewOrCreate, GetColorTransferFunction, OpenDataFile,
                             Render, SaveScreenshot, Show)

run, png = sys.argv[1], sys.argv[2]
field = sys.argv[3] if len(sys.argv) > 3 else "intact_bonds"
zoom = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
reader = OpenDataFile(run + "/particles.pvd")
reader.UpdatePipelineInformation()
times = reader.TimestepValues
view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [1200, 1200]
view.ViewTime = times[-1] if times else 0.0
display = Show(reader, view)
display.SetRepresentationType("Points")
display.PointSize = 3 if zoom <= 1 else 8
ColorBy(display, ("POINTS", field))
lut = GetColorTransferFunction(field)
display.RescaleTransferFunctionToDataRange(False, True)
display.SetScalarBarVisibility(view, True)
view.CameraPosition = [0, 0, 1.2]
view.CameraFocalPoint = [0, 0, 0]
view.CameraViewUp = [0, 1, 0]
view.ResetCamera()
Render(view)  # the first render resets the camera; set it after
if zoom > 1:
    bounds = reader.GetDataInformation().GetBounds()
    top = bounds[3]
    view.CameraFocalPoint = [0, 0.95 * top, 0]
    view.CameraPosition = [0, 0.95 * top, 1.2]
    view.CameraParallelProjection = 1
    view.CameraParallelScale = 0.5 * top / zoom
Render(view)
SaveScreenshot(png, view, ImageResolution=[1200, 1200])
print(f"render_ring: wrote {png} ({field} at t = {view.ViewTime:g} s)")
