#!/usr/bin/env python3
"""Real SPH data and the field's reference surface for `slosh bench accuracy --sph DIR`.

Runs SPlisHSPlasH (pysplishsplash) on its dam break at one particle radius, takes the
particles at each time asked for, and reconstructs them with splashsurf (pysplashsurf 0.14.1:
smoothing length 2r, cubes 0.5r, iso 0.6, given in particle radii; its docstring says
absolute lengths, its output says otherwise, so the edge length is checked). Writes, under
OUT/NAME-tTIME for each TIME:

  particles.ply   the particles (binary little-endian x y z, float32)
  splashsurf.ply  splashsurf's triangle mesh (binary little-endian, float32 vertices)
  meta.json       particle radius, time, splashsurf settings and seconds, particle count

usage: sph_reference.py OUT NAME RADIUS [TIME ...]   (default: 1)

The dam breaks the accuracy report shows (`docs/accuracy.md`) are

  sph_reference.py OUT coarse 0.025  0.3 0.4 0.5 0.6 0.8 1.0
  sph_reference.py OUT fine   0.0175 0.3 0.4 0.5 0.6 0.8 1.0

where the column collapses (0.3–0.5 s: it meets the far wall and rises along it) and when its
splash falls back (0.6–1 s).
  (pysplishsplash needs LD_PRELOAD=/lib/x86_64-linux-gnu/libGLdispatch.so.0 on Debian 12)
"""
import json
import os
import struct
import subprocess
import sys
import sysconfig
import tempfile
import time

import numpy as np


def scene_file(radius, work):
    """The dam break scene shipped with pysplishsplash, at `radius`, exporting VTK at 25 fps."""
    data = os.path.join(sysconfig.get_path("scripts"), "data")
    with open(os.path.join(data, "Scenes", "DamBreakModel.json")) as f:
        scene = json.load(f)
    c = scene["Configuration"]
    c["particleRadius"] = radius
    c["enableVTKExport"] = True
    c["dataExportFPS"] = 25
    c["particleAttributes"] = "velocity"
    for body in scene["RigidBodies"]:
        body["geometryFile"] = os.path.join(data, "models", os.path.basename(body["geometryFile"]))
    path = os.path.join(work, "scene.json")
    with open(path, "w") as f:
        json.dump(scene, f)
    return path


def simulate(scene, out, stop):
    """SPlisHSPlasH in a child process (its globals do not reset between runs)."""
    code = (
        "import sys, pysplishsplash as sph\n"
        "base = sph.Exec.SimulatorBase()\n"
        "base.init(['sim', '--no-gui', '--stopAt', sys.argv[3], '--output-dir', sys.argv[2],"
        " '--no-initial-pause', sys.argv[1]], 'SPlisHSPlasH')\n"
        "base.run()\n"
    )
    env = dict(os.environ, LD_PRELOAD="/lib/x86_64-linux-gnu/libGLdispatch.so.0")
    subprocess.run([sys.executable, "-c", code, scene, out, str(stop)], check=True, env=env,
                   stdout=subprocess.DEVNULL)


def read_vtk_points(path):
    """POINTS of a legacy binary VTK file (big-endian float32), as (N, 3) float64."""
    with open(path, "rb") as f:
        data = f.read()
    at = data.index(b"POINTS")
    line_end = data.index(b"\n", at)
    _, count, kind = data[at:line_end].split()
    if kind != b"float":
        raise ValueError(f"{path}: POINTS of {kind!r}, expected float")
    n = int(count)
    raw = np.frombuffer(data, dtype=">f4", count=3 * n, offset=line_end + 1)
    return raw.reshape(n, 3).astype(np.float64)


def write_ply(path, vertices, triangles=None):
    with open(path, "wb") as f:
        header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}",
                  "property float x", "property float y", "property float z"]
        if triangles is not None:
            header += [f"element face {len(triangles)}", "property list uchar int vertex_indices"]
        f.write(("\n".join(header + ["end_header"]) + "\n").encode())
        f.write(np.asarray(vertices, dtype="<f4").tobytes())
        if triangles is not None:
            tri = np.asarray(triangles, dtype="<i4")
            rows = np.empty(len(tri), dtype=[("n", "u1"), ("v", "<i4", 3)])
            rows["n"] = 3
            rows["v"] = tri
            f.write(rows.tobytes())


def main():
    out, name, radius = sys.argv[1], sys.argv[2], float(sys.argv[3])
    times = [float(t) for t in sys.argv[4:]] or [1.0]
    with tempfile.TemporaryDirectory() as work:
        # One run to the last time; each time is a frame of its 25 fps export.
        simulate(scene_file(radius, work), os.path.join(work, "sim"), max(times))
        for at in times:
            frame = int(round(at * 25))
            vtk = os.path.join(work, "sim", "vtk", f"ParticleData_Fluid_{frame}.vtk")
            reconstruct(read_vtk_points(vtk), os.path.join(out, f"{name}-t{at:g}"), radius, at)


def reconstruct(points, target, radius, at):
    """splashsurf's mesh of `points`, written with them and the meta data under `target`."""
    import pysplashsurf

    os.makedirs(target, exist_ok=True)
    # pysplashsurf 0.14.1's docstring calls these absolute lengths, but it scales smoothing
    # length and cube size by the particle radius (splashsurf's CLI convention): absolute
    # values give a mesh of a few thousandths of the radius per cube. So they are given as
    # multiples of r, and the mesh's edge length is checked against the cube size below.
    settings = {
        "particle_radius": radius,
        "smoothing_length": 2.0,
        "cube_size": 0.5,
        "iso_surface_threshold": 0.6,
    }
    start = time.perf_counter()
    mesh = pysplashsurf.reconstruct_surface(points.astype(np.float32), **settings)
    seconds = time.perf_counter() - start
    vertices = np.asarray(mesh.mesh.vertices if hasattr(mesh, "mesh") else mesh.vertices)
    triangles = np.asarray(mesh.mesh.triangles if hasattr(mesh, "mesh") else mesh.triangles)
    edges = np.linalg.norm(vertices[triangles[:, 0]] - vertices[triangles[:, 1]], axis=1)
    cube = settings["cube_size"] * radius
    if not 0.2 * cube < np.median(edges) < 2.0 * cube:
        raise SystemExit(f"splashsurf's median edge {np.median(edges):.3g} does not match cubes of {cube:.3g}")
    write_ply(os.path.join(target, "particles.ply"), points)
    write_ply(os.path.join(target, "splashsurf.ply"), vertices, triangles)
    meta = {
        "scene": "SPlisHSPlasH DamBreakModel (pysplishsplash)",
        "time": at,
        "particles": len(points),
        "particle_radius": radius,
        "splashsurf": {"version": "pysplashsurf 0.14.1", "in_particle_radii": settings,
                       "seconds": seconds, "triangles": len(triangles)},
    }
    with open(os.path.join(target, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)
    print(f"{target}: {len(points)} particles, {len(triangles)} triangles ({seconds:.2f} s)")


if __name__ == "__main__":
    main()
