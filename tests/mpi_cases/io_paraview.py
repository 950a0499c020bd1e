"""Run with ParaView's pvpython (not the venv python): open XDMF series, print what ParaView sees.

    pvpython io_paraview.py FILE.xdmf [FILE.xdmf ...]

Prints one JSON line per file: {"file", "times", "points": [...], "cells": [...], "arrays": [...],
"sums": {array: [sum per time]}} using the Xdmf3 reader that File > Open offers for .xdmf.
"""
import json
import sys

from paraview import servermanager
from paraview.simple import Xdmf3ReaderS

for filename in sys.argv[1:]:
    reader = Xdmf3ReaderS(FileName=filename)
    times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
    result = {"file": filename, "times": times, "points": [], "cells": [], "arrays": [], "sums": {}}
    for time in times:
        reader.UpdatePipeline(time)
        data = servermanager.Fetch(reader)
        if data.IsA("vtkMultiBlockDataSet"):
            data = data.GetBlock(0)
        result["points"].append(data.GetNumberOfPoints())
        result["cells"].append(data.GetNumberOfCells())
        for attributes in (data.GetPointData(), data.GetCellData()):
            for index in range(attributes.GetNumberOfArrays()):
                array = attributes.GetArray(index)
                name = array.GetName()
                if name not in result["arrays"]:
                    result["arrays"].append(name)
                total = 0.0
                for tuple_index in range(array.GetNumberOfTuples()):
                    total += sum(array.GetTuple(tuple_index))
                result["sums"].setdefault(name, []).append(total)
    print(json.dumps(result))
