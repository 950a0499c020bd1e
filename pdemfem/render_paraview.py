"""The ParaView half of `pdemfem render`: a script run by ParaView's own Python, not imported by pdemfem.

    pvpython --force-offscreen-rendering render_paraview.py JOB.json

pvpython has its own interpreter and packages, so this file uses only the standard library and
``paraview.simple``.  pdemfem/render.py writes the job (which files to open, the picture's size,
title and viewing direction) and runs this script in a subprocess; the script draws

- the particles of ``particles.xdmf`` (Xdmf3 reader, last time step) as sphere glyphs of their
  true radius (``radii``), coloured by speed (the magnitude of ``velocities``),
- each solid's ``<solid>.xdmf`` surface warped by its ``displacements`` (true scale), coloured by
  the displacement's magnitude,
- the walls from a legacy VTK polygon file (translucent),
- with ``color_by_temperature`` (heat on: the particles wrote ``temperature``), the particles and the
  solids coloured by ``temperature`` on one shared scale instead,

fits the camera to everything and saves the PNG.  On success it prints one JSON line
(``{"time": ..., "particles": N, "solids": [...], "paraview": "5.11.0"}``); any failure is a
Python traceback and a non-zero exit status, which pdemfem reports in one line.
"""
import json
import math
import sys

import paraview
from paraview import servermanager
from paraview.simple import (ColorBy, CreateView, ExtractSurface, GetColorTransferFunction, GetParaViewVersion,
                             GetScalarBar, Glyph, LegacyVTKReader, Render, ResetCamera, SaveScreenshot, Show,
                             Text, WarpByVector, Xdmf3ReaderS)

BACKGROUND = [1.0, 1.0, 1.0]
INK = [0.1, 0.1, 0.1]


def last_time(reader):
    """The reader's last time step (a series of one step gives a plain number, none gives 0)."""
    times = reader.TimestepValues
    if isinstance(times, (int, float)):
        return float(times)
    times = list(times) if times else []
    return times[-1] if times else 0.0


def point_array_names(source):
    return [source.PointData.GetArray(index).Name for index in range(source.PointData.GetNumberOfArrays())]


def fit_range(lookup, reader, name):
    """Colour the magnitudes of `name` from 0 to their largest value at the step the reader last
    updated (the last one; rescaling by the display would use the view's time, set only at the end).
    From 0, so that one rolling sphere or a uniform speed still gets a meaningful colour."""
    high = reader.PointData[name].GetRange(-1)[1]
    lookup.RescaleTransferFunction(0.0, high if high > 0 else 1.0)
    lookup.AutomaticRescaleRangeMode = "Never"


def color_by_magnitude(display, reader, view, name, preset, title, bars):
    """Colour `display` by the magnitude of point array `name` (fit_range) with its legend as the
    bars-th one; returns the number of legends now shown."""
    ColorBy(display, ("POINTS", name, "Magnitude"))
    lookup = GetColorTransferFunction(name)
    lookup.ApplyPreset(preset, True)
    fit_range(lookup, reader, name)
    lookup_bar(view, lookup, title, bars)
    return bars + 1


def color_by_temperature(displays, readers, view, bars):
    """Colour every display by point array ``temperature`` on one scale spanning all readers' values,
    with one legend; returns the number of legends now shown."""
    low, high = math.inf, -math.inf
    for reader in readers:
        if "temperature" in point_array_names(reader):
            first, last = reader.PointData["temperature"].GetRange(0)
            low, high = min(low, first), max(high, last)
    if not math.isfinite(low):
        return bars
    lookup = GetColorTransferFunction("temperature")
    lookup.ApplyPreset("Inferno (matplotlib)", True)
    for display in displays:
        ColorBy(display, ("POINTS", "temperature"))
    lookup.RescaleTransferFunction(low, high if high > low else low + 1.0)
    lookup.AutomaticRescaleRangeMode = "Never"
    lookup_bar(view, lookup, "temperature [K]", bars)
    return bars + 1


def main(job_file):
    with open(job_file) as handle:
        job = json.load(handle)
    width, height = job["size"]
    view = CreateView("RenderView")
    view.ViewSize = [width, height]
    view.Background = BACKGROUND
    # ParaView >= 5.10 draws its own background colour only when told to ignore the palette.
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 1
    view.OrientationAxesLabelColor = INK
    view.EnableRenderOnInteraction = 0
    report = {"paraview": getattr(paraview, "__version__", None) or "%d.%d" % tuple(GetParaViewVersion()),
              "solids": []}
    time = None
    bars = 0
    heat = bool(job.get("color_by_temperature"))
    heated = []  # (display, reader) coloured by temperature at the end, on one scale

    if job.get("walls"):
        walls = Show(LegacyVTKReader(FileNames=[job["walls"]]), view)
        walls.ColorArrayName = ["POINTS", ""]
        walls.AmbientColor = walls.DiffuseColor = [0.6, 0.6, 0.65]
        walls.Opacity = 0.18

    for path in job.get("solids", []):
        reader = Xdmf3ReaderS(FileName=path)
        solid_time = last_time(reader)
        reader.UpdatePipeline(solid_time)
        source = reader
        if "displacements" in point_array_names(reader):
            source = WarpByVector(Input=reader, Vectors=["POINTS", "displacements"], ScaleFactor=1.0)
        surface = ExtractSurface(Input=source)
        surface.UpdatePipeline(solid_time)
        display = Show(surface, view)
        if heat and "temperature" in point_array_names(reader):
            heated.append((display, reader))
        elif "displacements" in point_array_names(reader):
            # A solid under motion: coloured by its deformation, not by how far its frame carried it.
            field = ("elastic_displacements" if "elastic_displacements" in point_array_names(reader)
                     else "displacements")
            bars = color_by_magnitude(display, reader, view, field, "Plasma (matplotlib)",
                                      "displacement [m]" if field == "displacements" else "elastic displacement [m]",
                                      bars)
        display.EdgeColor = [0.2, 0.2, 0.2]
        time = solid_time if time is None else max(time, solid_time)
        report["solids"].append(servermanager.Fetch(surface).GetNumberOfCells())

    if job.get("particles"):
        reader = Xdmf3ReaderS(FileName=job["particles"])
        particle_time = last_time(reader)
        reader.UpdatePipeline(particle_time)
        names = point_array_names(reader)
        # The sphere source has radius 0.5: scaling by the radius times 2 draws the true size.
        glyphs = Glyph(Input=reader, GlyphType="Sphere")
        # Few particles are drawn large: smoother spheres cost nothing there.
        few = reader.GetDataInformation().GetNumberOfPoints() <= 100
        glyphs.GlyphType.ThetaResolution = 32 if few else 12
        glyphs.GlyphType.PhiResolution = 16 if few else 8
        glyphs.OrientationArray = ["POINTS", "No orientation array"]
        glyphs.GlyphMode = "All Points"
        if "radii" in names:
            glyphs.ScaleArray = ["POINTS", "radii"]
            glyphs.ScaleFactor = 2.0
        glyphs.UpdatePipeline(particle_time)
        display = Show(glyphs, view)
        if heat and "temperature" in names:
            heated.append((display, reader))
        elif "velocities" in names:
            bars = color_by_magnitude(display, reader, view, "velocities", "Viridis (matplotlib)", "speed [m/s]",
                                      bars)
        else:
            display.ColorArrayName = ["POINTS", ""]
            display.AmbientColor = display.DiffuseColor = [0.12, 0.47, 0.71]
        time = particle_time
        report["particles"] = servermanager.Fetch(reader).GetNumberOfPoints()

    if heated:
        bars = color_by_temperature([display for display, _ in heated], [reader for _, reader in heated], view, bars)
    view.ViewTime = time or 0.0
    report["time"] = time

    title = Text(Text=job["title"] + ("" if time is None else ", t = %.3g s" % time))
    label = Show(title, view)
    label.WindowLocation = "Upper Center"
    label.FontSize = 13
    label.Color = INK

    # The viewing direction of the matplotlib picture (elevation 30 deg, azimuth -60 deg, z up),
    # then ParaView fits the distance to everything shown.
    # paraview.simple resets the camera at a view's first render: render once before placing it.
    Render(view)
    elevation, azimuth = math.radians(job["elevation"]), math.radians(job["azimuth"])
    direction = [math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                 math.sin(elevation)]
    view.CameraFocalPoint = [0.0, 0.0, 0.0]
    view.CameraPosition = direction
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.CameraParallelProjection = 0
    if job.get("box"):
        # The box pdemfem fitted (with room around a few spheres, as in the matplotlib picture).
        (x0, y0, z0), (x1, y1, z1) = job["box"]
        view.ResetCamera(x0, x1, y0, y1, z0, z1)
    else:
        ResetCamera(view)
    if bars:
        # Keep the scene left of the colour legends (they take the right fifth of the picture): shift
        # the image left by a tenth of its width and step back to make room.
        camera = view.GetActiveCamera()
        camera.SetWindowCenter(0.2, 0.0)
        camera.Dolly(0.88)
    Render(view)
    SaveScreenshot(job["target"], view, ImageResolution=[width, height], TransparentBackground=0)
    print(json.dumps(report))


def lookup_bar(view, lookup, title, index):
    """Show the colour legend of `lookup` at the right edge (the second one below the first)."""
    bar = GetScalarBar(lookup, view)
    bar.Title = title
    bar.ComponentTitle = ""
    bar.HorizontalTitle = 1
    bar.RangeLabelFormat = "%-#.2g"
    bar.LabelFormat = "%-#.2g"
    bar.TitleColor = bar.LabelColor = INK
    bar.TitleFontSize = bar.LabelFontSize = 10
    bar.WindowLocation = "Any Location"
    bar.Orientation = "Vertical"
    bar.ScalarBarLength = 0.3
    bar.Position = [0.8, 0.55 - 0.47 * index]
    bar.Visibility = 1
    return bar


if __name__ == "__main__":
    main(sys.argv[1])
