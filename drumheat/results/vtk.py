"""ParaView output: particles as a VTK PolyData time series, the walls as a surface.

:func:`export_vtk` turns a result folder (``particles.npz`` + ``scene.toml``) into files that
ParaView (or any VTK reader) opens directly, written with numpy and the standard library only
(no VTK needed at run time):

- ``particles_0000.vtp``, ``particles_0001.vtp``, ...: one XML PolyData file per output time,
  the particle centres as points (each with a vertex cell, so they show without a filter) and
  the point arrays

    - ``radius`` (m): particle radius. In ParaView draw the particles to scale with the
      *Glyph* filter: glyph type *Sphere*, scale array ``radius``, scale factor 2 (the glyph
      sphere has radius 0.5);
    - ``temperature`` (K): particle temperature;
    - ``group`` (-): group index (the names are in the field data ``group_names``);
    - ``velocity`` (m/s): the particle's velocity where the run had a DEM; otherwise finite
      differences of the positions between outputs (central inside, one-sided at the ends;
      zeros for a resting bed);
    - ``id`` (-): particle index, the same at every time;
    - ``heat_rate`` (W): mean heat flow into the particle over the output interval ending at
      this time (:func:`drumheat.results.particles.heat_rates`; 0 at the first output), for
      lumped particles of a scene at hand;
    - where the run had a DEM (:func:`drumheat.mechanics.analysis.particle_mechanics`):
      ``angular_velocity`` (rad/s, a 3-vector; a 2D disc spins about z), ``force`` (N, the
      force without the particle's weight: its contacts), ``coordination`` (-, particles it
      overlaps) and ``wall_contacts`` (-, wall primitives it overlaps). Outputs of a replay
      (``dem.replay_after``) have no mechanics: these arrays are NaN there (ParaView's
      NaN colour) and the velocity is the finite difference of the recorded positions.

  Points are always 3D; a 2D scene has z = 0. The field data hold ``TIME`` (s) and the group
  names.
- ``particles.pvd``: the collection of these files with their times (ParaView: *File > Open*
  this file; the time controls then step through the outputs).
- ``walls.vtp``: the walls. In 2D the drum shell as a closed polyline in the plane z = 0; in
  3D a cylinder surface of radius D/2 and length ``drum.depth`` along z, placed over the
  particles (``0 <= z <= depth`` if no particle centre lies below z = 0, else centred on
  z = 0). Radial plates will become a line (2D) or a quad (3D) once scenes declare them
  (:func:`drumheat.results.plot.scene_walls`).

Coordinates follow DESIGN.md: drum axis through the origin (z in 3D), gravity along -y,
metres.
"""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

_VTK_TYPES = {np.dtype("<f8"): "Float64", np.dtype("<f4"): "Float32",
              np.dtype("<i4"): "Int32", np.dtype("<i8"): "Int64", np.dtype("u1"): "UInt8"}


def _mechanics_3d(mechanics: dict, dim: int) -> dict:
    """The per-particle mechanics as VTK point arrays: vectors (n_out, N, 3), a 2D spin as
    (0, 0, omega_z), counts (n_out, N, 1)."""
    out = {}
    for key, values in mechanics.items():
        values = np.asarray(values, float)
        if key == "angular_velocity" and dim == 2:
            values = np.stack([np.zeros_like(values), np.zeros_like(values), values], axis=-1)
        elif values.ndim == 3:
            values = _to_3d(values)
        else:
            values = values[..., None]
        out[key] = values
    return out


def _data_array(parent, name, values, n_components=1, binary=True):
    """Append a ``<DataArray>``: inline base64 (UInt64 byte-count header) or ASCII."""
    values = np.ascontiguousarray(values)
    if values.dtype.kind == "f":
        values = values.astype("<f8")
    elif values.dtype.kind in "iu" and values.dtype != np.dtype("u1"):
        values = values.astype("<i8") if values.dtype.itemsize > 4 else values.astype("<i4")
    attrs = {"type": _VTK_TYPES[values.dtype], "Name": name}
    if n_components > 1:
        attrs["NumberOfComponents"] = str(n_components)
    flat = values.reshape(-1)
    if binary:
        attrs["format"] = "binary"
        raw = flat.tobytes()
        header = np.array([len(raw)], dtype="<u8").tobytes()
        text = base64.b64encode(header).decode() + base64.b64encode(raw).decode()
    else:
        attrs["format"] = "ascii"
        if values.dtype.kind == "f":
            text = " ".join(f"{v:.17g}" for v in flat)
        else:
            text = " ".join(str(int(v)) for v in flat)
    el = ET.SubElement(parent, "DataArray", attrs)
    el.text = text
    return el


def _string_array(parent, name, strings):
    """Field-data array of strings (VTK's UInt8 encoding: bytes, each string NUL-terminated)."""
    raw = b"".join(s.encode() + b"\0" for s in strings)
    el = ET.SubElement(parent, "Array", {"type": "String", "Name": name,
                                          "NumberOfTuples": str(len(strings)),
                                          "format": "ascii"})
    el.text = " ".join(str(b) for b in raw)
    return el


def _polydata_xml(points, point_data=None, verts=None, lines=None, polys=None,
                  field_data=None, binary=True) -> ET.ElementTree:
    """An XML PolyData document.

    ``verts`` / ``lines`` / ``polys`` are lists of index lists (one per cell).
    """
    root = ET.Element("VTKFile", {"type": "PolyData", "version": "1.0",
                                  "byte_order": "LittleEndian", "header_type": "UInt64"})
    poly = ET.SubElement(root, "PolyData")
    if field_data:
        fd = ET.SubElement(poly, "FieldData")
        for name, value in field_data.items():
            if isinstance(value, (list, tuple)) and value and isinstance(value[0], str):
                _string_array(fd, name, value)
            else:
                arr = np.atleast_1d(np.asarray(value, float))
                el = _data_array(fd, name, arr, binary=False)
                el.set("NumberOfTuples", str(len(arr)))
    cells = {"Verts": verts or [], "Lines": lines or [], "Polys": polys or []}
    counts = {f"NumberOf{k}": str(len(v)) for k, v in cells.items()}
    piece = ET.SubElement(poly, "Piece", {"NumberOfPoints": str(len(points)), **counts,
                                          "NumberOfStrips": "0"})
    pd_el = ET.SubElement(piece, "PointData")
    for name, (values, ncomp) in (point_data or {}).items():
        _data_array(pd_el, name, values, ncomp, binary)
    pts = ET.SubElement(piece, "Points")
    _data_array(pts, "Points", np.asarray(points, float), 3, binary)
    for kind, cell_list in cells.items():
        el = ET.SubElement(piece, kind)
        conn = np.concatenate([np.asarray(c, int) for c in cell_list]) if cell_list else \
            np.zeros(0, int)
        offsets = np.cumsum([len(c) for c in cell_list]).astype(int)
        _data_array(el, "connectivity", conn, binary=binary)
        _data_array(el, "offsets", offsets, binary=binary)
    ET.indent(root, space=" ")
    return ET.ElementTree(root)


def _to_3d(position) -> np.ndarray:
    position = np.asarray(position, float)
    if position.shape[-1] == 3:
        return position
    pad = np.zeros(position.shape[:-1] + (3 - position.shape[-1],))
    return np.concatenate([position, pad], axis=-1)


def particle_velocities(t, position) -> np.ndarray:
    """Velocities from positions at the output times, m/s.

    Central differences on the (possibly non-uniform) output grid inside, one-sided at the
    first and last output (:func:`numpy.gradient`); zeros for a single output or a resting bed.

    Parameters
    ----------
    t : array_like (n_out,)
        Output times, s.
    position : array_like (n_out, N, dim)
        Centres, m.

    Returns
    -------
    ndarray (n_out, N, dim)
    """
    t = np.asarray(t, float)
    position = np.asarray(position, float)
    if len(t) < 2:
        return np.zeros_like(position)
    v = np.gradient(position, t, axis=0)
    resting = np.all(np.diff(position, axis=0) == 0, axis=0)  # (N, dim): exactly still
    return np.where(resting[None], 0.0, v)


def wall_geometry(walls, dim, z_range=(0.0, 0.0), n_segments=128):
    """Points and cells of wall descriptions for a ``walls.vtp`` file.

    Parameters
    ----------
    walls : sequence
        Wall descriptions (:func:`drumheat.results.plot.wall_description`).
    dim : {2, 3}
        2: circles as closed polylines and plates as lines in z = 0; 3: cylinder surfaces
        (quads) and plates (one quad) between ``z_range``.
    z_range : (float, float)
        Axial extent in 3D, m.
    n_segments : int
        Segments per circle.

    Returns
    -------
    points : ndarray (P, 3)
    lines, polys : list of index lists
    """
    from drumheat.results.plot import wall_description

    points, lines, polys = [], [], []
    z0, z1 = map(float, z_range)

    def add(p):
        points.append(p)
        return len(points) - 1

    for w in walls:
        d = wall_description(w)
        if d["kind"] == "circle":
            phi = np.linspace(0.0, 2 * np.pi, n_segments, endpoint=False)
            xy = np.asarray(d["center"]) + d["radius"] * np.stack([np.cos(phi), np.sin(phi)], 1)
            if dim == 2:
                ids = [add((x, y, 0.0)) for x, y in xy]
                lines.append(ids + [ids[0]])
            else:
                lo = [add((x, y, z0)) for x, y in xy]
                hi = [add((x, y, z1)) for x, y in xy]
                for k in range(n_segments):
                    m = (k + 1) % n_segments
                    polys.append([lo[k], lo[m], hi[m], hi[k]])
        elif d["kind"] == "segment":
            (xa, ya), (xb, yb) = d["start"], d["end"]
            if dim == 2:
                lines.append([add((xa, ya, 0.0)), add((xb, yb, 0.0))])
            else:
                polys.append([add((xa, ya, z0)), add((xb, yb, z0)), add((xb, yb, z1)),
                              add((xa, ya, z1))])
    return np.asarray(points, float).reshape(-1, 3), lines, polys


def _z_range(frames):
    depth = getattr(frames.scene.drum, "depth", None) if frames.scene is not None else None
    if frames.dim < 3:
        return (0.0, 0.0)
    z = frames.position[..., 2]
    r = 0.5 * float(np.max(frames.diameter))
    if depth is None:
        return (float(z.min()) - r, float(z.max()) + r)
    if z.min() >= -1e-12:
        return (0.0, float(depth))
    return (-0.5 * float(depth), 0.5 * float(depth))


def export_vtk(result_dir, out_dir=None, binary: bool = True, n_segments: int = 128) -> Path:
    """Write a result folder as ParaView files: a ``.vtp`` per output, ``.pvd``, walls.

    Parameters
    ----------
    result_dir : str or Path
        Result folder with ``particles.npz`` (``t``, ``T``, ``group``, ``diameter``,
        ``position``) and ``scene.toml`` (for the walls).
    out_dir : str or Path, optional
        Output folder; default ``<result_dir>/vtk``. Existing files of the same names are
        replaced; the files are first written to a temporary folder beside it.
    binary : bool
        Inline base64 binary data (default, compact) or ASCII.
    n_segments : int
        Segments of the drum circle.

    Returns
    -------
    Path
        The ``particles.pvd`` file.

    Raises
    ------
    drumheat.results.plot.ResultFolderError
        Missing folder, ``particles.npz`` or arrays (a :class:`FileNotFoundError`).
    """
    import shutil
    import tempfile

    from drumheat.results.particles import heat_rates
    from drumheat.results.plot import read_particles, scene_walls

    frames = read_particles(result_dir)
    out = Path(out_dir) if out_dir is not None else Path(result_dir) / "vtk"
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        pos3 = _to_3d(frames.position)
        vel = _to_3d(particle_velocities(frames.t, frames.position))
        mech = _mechanics_3d(frames.mechanics, frames.dim)
        if "velocity" in mech:  # the DEM's own, where it ran (finite differences in a replay)
            vel = np.where(np.isnan(mech["velocity"]), vel, mech.pop("velocity"))
        q = heat_rates(frames)
        n = pos3.shape[1]
        radius = 0.5 * frames.diameter
        ids = np.arange(n)
        verts = [[i] for i in range(n)]
        names = [str(s) for s in frames.group_names] or ["particles"]
        collection = ET.Element("VTKFile", {"type": "Collection", "version": "1.0",
                                            "byte_order": "LittleEndian",
                                            "header_type": "UInt64"})
        coll = ET.SubElement(collection, "Collection")
        width = max(4, len(str(len(frames.t) - 1)))
        for k, t in enumerate(frames.t):
            name = f"particles_{k:0{width}d}.vtp"
            point_data = {"radius": (radius, 1), "temperature": (frames.T[k], 1),
                          "group": (frames.group.astype(np.int32), 1),
                          "velocity": (vel[k], 3), "id": (ids.astype(np.int32), 1)}
            if q is not None:  # W into each particle over the interval ending here
                point_data["heat_rate"] = (np.nan_to_num(q[k]), 1)
            for key, values in mech.items():
                point_data[key] = (values[k], values.shape[-1])
            doc = _polydata_xml(
                pos3[k], point_data=point_data,
                verts=verts, field_data={"TIME": [float(t)], "group_names": names},
                binary=binary)
            doc.write(tmp / name, encoding="utf-8", xml_declaration=True)
            ET.SubElement(coll, "DataSet", {"timestep": repr(float(t)), "group": "",
                                            "part": "0", "file": name})
        ET.indent(collection, space=" ")
        ET.ElementTree(collection).write(tmp / "particles.pvd", encoding="utf-8",
                                         xml_declaration=True)
        walls = scene_walls(frames.scene)
        dim = 3 if frames.dim == 3 else 2
        pts, lines, polys = wall_geometry(walls, dim, _z_range(frames), n_segments)
        _polydata_xml(pts, lines=lines, polys=polys, binary=binary).write(
            tmp / "walls.vtp", encoding="utf-8", xml_declaration=True)
        out.mkdir(parents=True, exist_ok=True)
        for old in list(out.glob("particles_*.vtp")):
            old.unlink()
        for f in tmp.iterdir():
            shutil.move(str(f), out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if out.resolve().parent == Path(result_dir).resolve():
        from drumheat.results.files import register_outputs

        register_outputs(result_dir, [out.name])
    return out / "particles.pvd"
