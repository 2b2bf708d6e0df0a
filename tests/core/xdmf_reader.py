"""The XDMF sidecar of `octocd run --trace` loads in ParaView's Xdmf3 reader (ctest
`core.xdmf_reader`, label `unit`).

    xdmf_reader.py OCTOCD SOURCE_DIR WORK_DIR

Runs a 20-frame box-stack with a state row every 5 frames, then:
1. a schema check of the sidecar against the trace (h5py): an XDMF 3 temporal collection
   of one Polyvertex grid per state row, each HDF item naming a dataset of the trace with
   matching dimensions and number type, hyperslabs inside their dataset;
2. VTK's vtkXdmf3Reader (ParaView's "XDMF Reader (Xdmf3)", Debian's python3-paraview):
   every time step loads with one point per body at that row's positions, and the
   velocity, half_extents and group_id point arrays.
Exit 0 when both pass, 1 naming what differs, 77 (ctest: skipped) after a passing schema
check when the reader is not installed, saying so.
"""
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

NUMBER_TYPES = {("Float", "4"): np.float32, ("Float", "8"): np.float64, ("Int", "4"): np.int32,
                ("UInt", "4"): np.uint32, ("Int", "8"): np.int64}
SKIP = 77


def fail(msg):
    print(f"FAIL: {msg}")
    sys.exit(1)


def ints(text):
    return [int(v) for v in text.split()]


def schema_check(xmf, trace):
    """Returns the per-grid (time, state row) list; fails on any mismatch."""
    root = ET.parse(xmf).getroot()
    if root.tag != "Xdmf" or root.get("Version") != "3.0":
        fail(f"{xmf}: root is <{root.tag} Version={root.get('Version')}>, expected <Xdmf Version=3.0>")
    coll = root.findall("./Domain/Grid")
    if len(coll) != 1 or coll[0].get("CollectionType") != "Temporal":
        fail(f"{xmf}: expected one temporal collection under Domain")
    grids = coll[0].findall("./Grid")
    frames = trace["/states/frame"][:]
    nb = trace["/bodies/inverse_mass"].shape[0]
    if len(grids) != len(frames):
        fail(f"{xmf}: {len(grids)} grids for {len(frames)} state rows")
    for g, grid in enumerate(grids):
        topo = grid.find("Topology")
        if topo is None or topo.get("TopologyType") != "Polyvertex" or int(topo.get("NumberOfElements")) != nb:
            fail(f"{xmf}: grid {g}: Topology must be Polyvertex of {nb} elements")
        if grid.find("Geometry") is None or grid.find("Geometry").get("GeometryType") != "XYZ":
            fail(f"{xmf}: grid {g}: Geometry must be XYZ")
        items = grid.findall(".//DataItem")
        if any(i.get("ItemType") not in (None, "Uniform") for i in items):
            fail(f"{xmf}: grid {g}: only plain HDF items (ParaView's Xdmf3 readers leave other item types untyped)")
        for item in items:
            if item.get("Format") != "HDF":
                fail(f"{xmf}: grid {g}: item Format {item.get('Format')}, expected HDF")
            ref = item.text.strip()
            fname, _, rest = ref.partition(":")
            if fname != os.path.basename(trace.filename):
                fail(f"{xmf}: item names file {fname!r}, not the trace")
            dataset, bar, slab = rest.partition("|")
            if dataset not in trace:
                fail(f"{xmf}: item names {dataset!r}, which the trace lacks")
            ds = trace[dataset]
            want = NUMBER_TYPES.get((item.get("NumberType"), item.get("Precision")))
            if want is None or np.dtype(want) != ds.dtype.newbyteorder("="):
                fail(f"{xmf}: {dataset}: NumberType {item.get('NumberType')} Precision {item.get('Precision')} vs dtype {ds.dtype}")
            dims = ints(item.get("Dimensions"))
            if not bar:
                if tuple(dims) != ds.shape:
                    fail(f"{xmf}: {dataset}: Dimensions {dims} vs {ds.shape}")
                continue
            groups = [ints(x) for x in slab.split(":")]
            if len(groups) != 4 or any(len(x) != ds.ndim for x in groups):
                fail(f"{xmf}: {ref}: expected start:stride:count:dims with {ds.ndim} values each")
            start, stride, count, ddims = groups
            if tuple(ddims) != ds.shape or any(s + c > d for s, c, d in zip(start, count, ddims)):
                fail(f"{xmf}: {ref}: outside the dataset of shape {ds.shape}")
            if [c for c in count if c != 1] != [c for c in dims if c != 1]:
                fail(f"{xmf}: {ref}: count {count} vs Dimensions {dims}")
            if dataset.startswith("/states/") and start[0] != g:
                fail(f"{xmf}: grid {g} reads state row {start[0]}")
    return len(grids), nb


def main(octocd, source, work):
    os.makedirs(work, exist_ok=True)
    h5 = os.path.join(work, "xdmf-box-stack.h5")
    scene = os.path.join(source, "datasets", "scenes", "box-stack.json")
    r = subprocess.run([octocd, "run", scene, "--frames", "20", "--state-every", "5", "--trace", h5, "--quiet"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"octocd run exited {r.returncode}: {r.stderr}")
    xmf = h5 + ".xmf"
    with h5py.File(h5, "r") as trace:
        rows, nb = schema_check(xmf, trace)
        positions = trace["/states/position"][:]
        dt = float(trace.attrs["dt"])
        frames = trace["/states/frame"][:]
    print(f"schema check: {rows} grids of {nb} bodies match the trace")
    try:
        from vtkmodules.vtkIOXdmf3 import vtkXdmf3Reader
        from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as Pipeline
        from vtkmodules.util.numpy_support import vtk_to_numpy
    except ImportError as e:
        print(f"SKIPPED the reader check: VTK's XDMF3 reader is not installed ({e}); "
              "Debian's python3-paraview provides it")
        return SKIP
    reader = vtkXdmf3Reader()
    reader.SetFileName(os.path.abspath(xmf))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(Pipeline.TIME_STEPS())
    if times is None or len(times) != rows:
        fail(f"reader: time steps {times}, expected {rows}")
    for r, t in enumerate(times):
        if abs(t - frames[r] * dt) > 1e-6:
            fail(f"reader: time step {r} at {t}, expected {frames[r] * dt}")
        reader.UpdateTimeStep(t)
        out = reader.GetOutputDataObject(0)
        if out.GetNumberOfPoints() != nb:
            fail(f"reader: time step {r}: {out.GetNumberOfPoints()} points, expected {nb} (one per body)")
        got = vtk_to_numpy(out.GetPoints().GetData())
        if not np.array_equal(got, positions[r]):
            fail(f"reader: time step {r}: points differ from /states/position[{r}]")
        pd = out.GetPointData()
        names = {pd.GetArrayName(i) for i in range(pd.GetNumberOfArrays())}
        if not {"velocity", "half_extents", "group_id"} <= names:
            fail(f"reader: time step {r}: point arrays {sorted(names)}")
    print(f"vtkXdmf3Reader: {rows} time steps of {nb} points, positions equal to the trace's")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
