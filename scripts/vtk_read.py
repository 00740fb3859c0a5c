#!/usr/bin/env python3
"""Reads an EnSight case with VTK's vtkGenericEnSightReader and prints, per time step, the
point count and a digest of every point array (as JSON), for comparison with slosh's reader.

usage: vtk_read.py CASE [--values]   (--values also prints every value; keep cases small)
"""
import json
import sys

import vtk
from vtk.util.numpy_support import vtk_to_numpy


def blocks(data):
    """Every vtkDataSet leaf of a composite output, in order."""
    it = data.NewIterator()
    it.InitTraversal()
    while not it.IsDoneWithTraversal():
        yield it.GetCurrentDataObject()
        it.GoToNextItem()


def main():
    case = sys.argv[1]
    values = "--values" in sys.argv
    reader = vtk.vtkGenericEnSightReader()
    reader.SetCaseFileName(case)
    reader.ReadAllVariablesOn()
    reader.UpdateInformation()
    times = [reader.GetTimeSets().GetItem(0).GetValue(i) for i in range(reader.GetTimeSets().GetItem(0).GetNumberOfTuples())] if reader.GetTimeSets().GetNumberOfItems() else [0.0]
    out = {"reader": reader.GetReader().GetClassName() if reader.GetReader() else None, "steps": []}
    for t in times:
        reader.SetTimeValue(t)
        reader.Update()
        step = {"time": t, "points": 0, "positions": [], "arrays": {}}
        for ds in blocks(reader.GetOutput()):
            n = ds.GetNumberOfPoints()
            if n == 0:
                continue
            step["points"] += n
            step["positions"].extend(vtk_to_numpy(ds.GetPoints().GetData()).astype(float).ravel().tolist())
            pd = ds.GetPointData()
            for i in range(pd.GetNumberOfArrays()):
                arr = pd.GetArray(i)
                step["arrays"].setdefault(arr.GetName(), []).extend(vtk_to_numpy(arr).astype(float).ravel().tolist())
        if not values:
            step["positions"] = len(step["positions"])
            step["arrays"] = {k: len(v) for k, v in step["arrays"].items()}
        out["steps"].append(step)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
