"""Mesh files -> PUT /complex bodies (clients read mesh files, the daemon takes JSON: docs/API.md).

Formats: OBJ, OFF and TetGen .node/.ele, read here (_read_obj, _read_off, _read_tetgen: OBJ
points, polylines and faces, OFF faces of any size, which meshio's readers drop or refuse;
meshio's TetGen reader loops forever on a file without a header line); STL, Gmsh .msh (2.2
and 4.1, ASCII or binary), VTK legacy .vtk, VTK XML .vtu, read with meshio (Debian
python3-meshio); plus .json, a PUT /complex body used as it is. Cells become simplices: vertex,
line, triangle and tetra as they are; quads and polygons are split into triangles around their
first vertex; other cell kinds (hexahedra, wedges, pyramids, quadratic cells) are refused with
MeshError, since the daemon's complex is simplicial. Every point is posted in the file's order
(as meshio reads it; STL points are merged),
so indices in a tags file are the file's point numbers, 0-based. Numeric point data become
attributes (names outside [A-Za-z0-9_-] are rewritten with "_"; meshio's own "gmsh:", "obj:" ...
arrays are left out).

Gmsh physical groups name tags: the cells of the groups chosen as singular (by default every group
whose name starts with "singular", "crease" or "corner", case-insensitive) become singular
simplices of PUT /tags — points are corners, lines creases, triangles embedded surfaces.

With fill, the 2-D cells (triangles, split quads and polygons) become the surface of a "fill" entry (TetGen tetrahedralizes what they
enclose) instead of simplices.
"""
import contextlib
import io
import json
import math
import pathlib
import re
import types

FORMATS = {".obj": "obj", ".off": "off", ".stl": "stl", ".msh": "gmsh", ".vtk": "vtk",
           ".vtu": "vtu", ".node": "tetgen", ".ele": "tetgen", ".json": "json"}
DEFAULT_SINGULAR = ("singular", "crease", "corner")
SKIP_DATA = re.compile(r"^(gmsh|obj|medit|flac3d|tetgen|ansys|abaqus|permas|avsucd|vtk):|^facet_normals$")


class MeshError(Exception):
    """The file cannot be read or turned into a simplicial complex (CLI exit code 2)."""


def read(path, *, fill=None, singular_groups=None):
    """Read the mesh file at `path`; returns the pair (body, tags).

    `body` is a PUT /complex body (docs/API.md), a dict of plain Python lists ready for
    `Session.put_complex(body)` or `json.dump`:
      "vertices"    [[x, y, z], ...] floats, one per point of the file in its order (2-D points
                    get z = 0);
      "simplices"   [[i], [i, j], [i, j, k], [i, j, k, l], ...] 0-based point indices, the
                    file's vertex, line, triangle and tetra cells (quads and polygons split into
                    triangles); with `fill` without the 2-D cells, and left out when there
                    is nothing else;
      "fill"        only with `fill`: [dict(fill, surface=[[i, j, k], ...])], the file's
                    2-D cells: triangles, and quads and polygons split into triangles;
      "attributes"  only when the file has numeric point data: {name: [v, ...]} for one
                    component, {name: [[v0, v1, ...], ...]} for more (at most 16 arrays).
    A .json file is its own body (with `fill`, its triangles moved into a "fill" entry).

    `tags` is the list of singular simplices from the chosen Gmsh physical groups, each a sorted
    list of point indices ([i] corner, [i, j] crease, [i, j, k] embedded triangle), duplicates
    dropped, in file order — the "singular" of a PUT /tags body (`Session.put_tags(tags)`); [] when
    groups were chosen but hold none of those cells; None when no group was chosen (not a Gmsh
    file, no group with a default prefix, `singular_groups=[]`, or a .json file).

    `fill`: None, or a dict of fill switches ({"max_volume": v, "min_ratio": r}) to post the
    2-D cells as a fill surface. `singular_groups`: names of the physical groups that are tags
    (None: the groups whose names start with "singular", "crease" or "corner", case-insensitive;
    a name the file lacks raises MeshError). Raises MeshError when the file cannot be read or is
    not simplicial."""
    p = pathlib.Path(path)
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise MeshError(f"{path}: unknown mesh format {p.suffix!r}; use one of "
                        + ", ".join(sorted(FORMATS)))
    if not p.exists():
        raise MeshError(f"{path}: no such file")
    if kind == "json":
        try:
            body = json.loads(p.read_text())
        except (ValueError, UnicodeDecodeError) as e:
            raise MeshError(f"{path}: not a JSON document: {e}") from e
        if not isinstance(body, dict):
            raise MeshError(f"{path}: a complex is a JSON object (a PUT /complex body)")
        if fill is not None:
            tris = [s for s in body.get("simplices", []) if len(s) == 3]
            body["simplices"] = [s for s in body.get("simplices", []) if len(s) != 3]
            body.setdefault("fill", []).append(dict(fill, surface=tris))
        return body, None
    if kind == "tetgen":
        m = _read_tetgen(p.with_suffix(".node"), p.with_suffix(".ele"))
        return from_meshio(m, path=str(path), fill=fill, singular_groups=singular_groups)
    if kind in ("obj", "off"):
        try:
            text = p.read_text()
        except UnicodeDecodeError as e:
            raise MeshError(f"{path}: not a text {kind.upper()} file: {e}") from e
        m = (_read_obj if kind == "obj" else _read_off)(text, str(path))
        return from_meshio(m, path=str(path), fill=fill, singular_groups=singular_groups)
    try:
        import meshio
    except ImportError as e:  # pragma: no cover - Debian python3-meshio is in tools/packages.txt
        raise MeshError("reading mesh files needs meshio (Debian: python3-meshio)") from e
    # meshio raises many kinds (ValueError, KeyError ...); and for its own ReadError, meshio.read
    # prints the message and calls sys.exit(1) (meshio._helpers._read_file). Its output is
    # captured, so that the message becomes the MeshError's and nothing else is printed.
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            m = meshio.read(str(p), file_format=kind)
    except SystemExit as e:
        why = " ".join(said.getvalue().split()) or f"exit status {e.code}"
        raise MeshError(f"{path}: meshio could not read it as {kind}: {why}") from None
    except Exception as e:
        raise MeshError(f"{path}: meshio could not read it as {kind}: {type(e).__name__}: {e}") from e
    return from_meshio(m, path=str(path), fill=fill, singular_groups=singular_groups)


class _Block:
    """A run of cells of one kind, as a meshio CellBlock (.type, .data)."""

    def __init__(self, type_):
        self.type, self.data = type_, []


def _mesh(points, cells):
    """What from_meshio reads of a meshio.Mesh: points, cell blocks (consecutive cells of one
    kind, in file order) and no data."""
    blocks = []
    for kind, c in cells:
        if not blocks or blocks[-1].type != kind:
            blocks.append(_Block(kind))
        blocks[-1].data.append(c)
    return types.SimpleNamespace(points=points, cells=blocks, cell_data={}, field_data={},
                                 point_data={})


def _xyz(words, error):
    """The first three words as a point (further ones ignored), or MeshError(error)."""
    try:
        xyz = [float(x) for x in words[:3]]
    except ValueError:
        xyz = []
    if len(xyz) != 3:
        raise MeshError(error)
    return xyz


def _face_kind(n):
    return {1: "vertex", 2: "line", 3: "triangle", 4: "quad"}.get(n, "polygon")


def _read_obj(text, path):
    """Wavefront OBJ: "v x y z" points (further numbers, w or a colour, ignored), "p i j ..."
    points, "l i j k ..." polylines (a segment per consecutive pair), "f i j k ..." faces
    (triangles, quads, polygons); an index is 1-based, negative counts back from the last "v",
    and "i/t/n" forms keep i. Normals, texture coordinates, groups, objects, smoothing and
    materials are ignored; free-form geometry is refused."""
    points, cells = [], []
    lines, part, first = [], "", None  # (the line a record starts on, the record)
    for no, raw in enumerate(text.splitlines(), 1):
        first = first or no
        if raw.endswith("\\"):  # continued on the next line
            part += raw[:-1] + " "
            continue
        lines.append((first, part + raw))
        part, first = "", None
    if first:
        lines.append((first, part))
    for no, line in lines:
        w = line.split("#", 1)[0].split()
        if not w:
            continue
        key, args = w[0], w[1:]
        where = f"{path}: line {no}"
        if key == "v":
            points.append(_xyz(args, f"{where}: a vertex is \"v x y z\""))
        elif key in ("p", "l", "f"):
            idx = []
            for a in args:
                try:
                    i = int(a.split("/", 1)[0])
                except ValueError:
                    raise MeshError(f"{where}: {a!r} is not a vertex index") from None
                j = i - 1 if i > 0 else len(points) + i
                if i == 0 or not 0 <= j < len(points):
                    raise MeshError(f"{where}: vertex index {i} is not one of the "
                                    f"{len(points)} vertices before it")
                idx.append(j)
            need = {"p": 1, "l": 2, "f": 3}[key]
            if len(idx) < need:
                raise MeshError(f"{where}: \"{key}\" needs at least {need} vertex indices")
            if key == "p":
                cells += [("vertex", [i]) for i in idx]
            elif key == "l":
                cells += [("line", idx[k:k + 2]) for k in range(len(idx) - 1)]
            else:
                cells.append((_face_kind(len(idx)), idx))
        elif key in ("curv", "curv2", "surf", "cstype"):
            raise MeshError(f"{where}: free-form geometry ({key}) is not supported; "
                            "export the mesh as polygons")
    if not points:
        raise MeshError(f"{path}: no \"v\" records: not an OBJ mesh")
    return _mesh(points, cells)


def _read_off(text, path):
    """OFF (Geomview): a header "OFF" (or COFF, NOFF, STOFF ...: extra vertex numbers
    ignored), the counts "V F [E]", V lines "x y z ...", F lines "n i1 ... in [colour]" with
    0-based indices: a face of 1 or 2 vertices is a point or a segment, 3 a triangle, more a
    polygon. Comments start with "#"; each vertex and face is on a line of its own."""
    rows = []
    for no, line in enumerate(text.splitlines(), 1):
        w = line.split("#", 1)[0].split()
        if w:
            rows.append((no, w))
    if not rows or not rows[0][1][0].endswith("OFF") \
            or rows[0][1][0][:-3] not in ("", "C", "N", "CN", "ST", "STC", "STN", "STCN"):
        raise MeshError(f"{path}: not an OFF file (the first line is not \"OFF\"; "
                        "4OFF, nOFF and binary OFF are not supported)")
    head = rows[0][1][1:]
    if head == ["BINARY"] or (head and head[0] == "BINARY"):
        raise MeshError(f"{path}: binary OFF is not supported")
    at = 1
    if not head:
        if len(rows) < 2:
            raise MeshError(f"{path}: no vertex and face counts")
        head, at = rows[1][1], 2
    try:
        nv, nf = int(head[0]), int(head[1])
    except (ValueError, IndexError):
        raise MeshError(f"{path}: the counts line is \"vertices faces [edges]\"") from None
    if nv < 0 or nf < 0 or len(rows) < at + nv + nf:
        raise MeshError(f"{path}: {nv} vertices and {nf} faces announced, the file has "
                        f"{max(len(rows) - at, 0)} lines of them")
    points, cells = [], []
    for no, w in rows[at:at + nv]:
        points.append(_xyz(w, f"{path}: line {no}: a vertex is \"x y z\""))
    for no, w in rows[at + nv:at + nv + nf]:
        try:
            n = int(w[0])
            idx = [int(x) for x in w[1:1 + n]]
        except ValueError:
            raise MeshError(f"{path}: line {no}: a face is \"n i1 ... in\"") from None
        if n < 1 or len(idx) != n:
            raise MeshError(f"{path}: line {no}: a face is \"n i1 ... in\" with n >= 1")
        if any(not 0 <= i < nv for i in idx):
            raise MeshError(f"{path}: line {no}: a vertex index is not one of 0..{nv - 1}")
        cells.append((_face_kind(n), idx))
    return _mesh(points, cells)


def _rows(path):
    """The (line number, words) of a TetGen file's lines, "#" comments and blank lines left out."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise MeshError(f"{path}: no such file (TetGen meshes are a .node and an .ele "
                        "file of the same name)") from None
    except UnicodeDecodeError as e:
        raise MeshError(f"{path}: not a text TetGen file: {e}") from e
    rows = []
    for no, line in enumerate(text.splitlines(), 1):
        w = line.split("#", 1)[0].split()
        if w:
            rows.append((no, w))
    return rows


def _counts(path, rows, what, per_what, want):
    """The header line's first two numbers (the count and the numbers per row) and the rows
    after it, checked to hold the count of rows of that many numbers (further ones ignored)."""
    if not rows:
        raise MeshError(f"{path}: no header line \"<{what}> ...\": not a TetGen file")
    no, w = rows[0]
    try:
        n, per = int(w[0]), int(w[1])
    except (ValueError, IndexError):
        raise MeshError(f"{path}: line {no}: the header is \"<{what}> ...\"") from None
    if n < 1:
        raise MeshError(f"{path}: line {no}: {n} {what}; at least 1 is needed")
    if per != want:
        raise MeshError(f"{path}: line {no}: {per_what} {per}; only {want} is read")
    if len(rows) - 1 < n:
        raise MeshError(f"{path}: {n} {what} announced, the file has {len(rows) - 1} lines of them")
    return n, rows[1:n + 1]


def _read_tetgen(node, ele):
    """TetGen .node ("<points> 3 <attributes> <markers>", then "<i> x y z ...") and .ele
    ("<tetrahedra> 4 <attributes>", then "<i> a b c d ..."); points numbered consecutively from
    the first one's number (0 or 1), which the .ele's indices count from; "#" comments anywhere;
    attributes and markers ignored."""
    n, rows = _counts(node, _rows(node), "points", "dimension", 3)
    points, base = [], None
    for k, (no, w) in enumerate(rows):
        try:
            i = int(w[0])
        except ValueError:
            raise MeshError(f"{node}: line {no}: a point is \"<number> x y z\"") from None
        base = i if base is None else base
        if i != base + k:
            raise MeshError(f"{node}: line {no}: point {i} should be number {base + k} "
                            "(points are numbered consecutively)")
        points.append(_xyz(w[1:], f"{node}: line {no}: a point is \"<number> x y z\""))
    nt, rows = _counts(ele, _rows(ele), "tetrahedra", "nodes per tetrahedron", 4)
    cells = []
    for no, w in rows:
        try:
            idx = [int(x) - base for x in w[1:5]]
        except ValueError:
            idx = []
        if len(idx) != 4:
            raise MeshError(f"{ele}: line {no}: a tetrahedron is \"<number> a b c d\"")
        if any(not 0 <= i < n for i in idx):
            raise MeshError(f"{ele}: line {no}: a point number is not one of "
                            f"{base}..{base + n - 1}")
        cells.append(("tetra", idx))
    return _mesh(points, cells)


SIZES = {"vertex": 1, "line": 2, "triangle": 3, "tetra": 4, "quad": 4}


def _cells(kind, cells, npoints, path):
    """The cells of a block as lists of ints, each of the size its kind has (a binary file cut
    short can leave meshio a tetra block of 2-number rows) and naming one of the points."""
    out = []
    for k, c in enumerate(cells):
        c = [int(i) for i in c]
        if len(c) != SIZES.get(kind, max(len(c), 3)):
            raise MeshError(f"{path}: {kind} cell {k} has {len(c)} point indices; the file may "
                            "be cut short or damaged")
        if any(not 0 <= i < npoints for i in c):
            raise MeshError(f"{path}: {kind} cell {k} names a point that is not one of the "
                            f"{npoints} of the file")
        out.append(c)
    return out


def _split(kind, cells, path, npoints):
    """Simplices of one meshio cell block."""
    if kind in ("vertex", "line", "triangle", "tetra"):
        return _cells(kind, cells, npoints, path)
    if kind in ("quad",) or kind.startswith("polygon"):
        out = []
        for c in _cells(kind, cells, npoints, path):
            out += [[c[0], c[i], c[i + 1]] for i in range(1, len(c) - 1)]
        return out
    raise MeshError(f"{path}: cells of kind {kind!r} are not simplices; the daemon takes points, "
                    "lines, triangles and tetrahedra (convert the mesh, e.g. with gmsh)")


def from_meshio(m, *, path="mesh", fill=None, singular_groups=None):
    """(body, tags) of a meshio.Mesh, as read() returns them; `path` names it in errors."""
    verts = [[float(x) for x in (list(p) + [0.0, 0.0])[:3]] for p in m.points]
    if not verts:
        raise MeshError(f"{path}: the mesh has no points")
    for k, v in enumerate(verts):
        if not all(math.isfinite(x) for x in v):
            raise MeshError(f"{path}: point {k} (0-based, in file order) has a non-finite "
                            f"coordinate: {v}")
    simplices, surface = [], []
    phys = m.cell_data.get("gmsh:physical")
    groups = {}  # physical tag -> name, for the chosen singular groups
    names = {str(k): v for k, v in (m.field_data or {}).items()}
    if singular_groups is None:
        chosen = {k for k in names if k.lower().startswith(DEFAULT_SINGULAR)}
    else:
        chosen = set(singular_groups)
        missing = chosen - set(names)
        if missing:
            raise MeshError(f"{path}: no physical group named {', '.join(sorted(missing))} "
                            f"(the file has: {', '.join(sorted(names)) or 'none'})")
    for name in chosen:
        tag, dim = int(names[name][0]), int(names[name][1])
        groups[(dim, tag)] = name
    tags = []
    dims = {"vertex": 0, "line": 1, "triangle": 2, "tetra": 3}
    for b, block in enumerate(m.cells):
        s = _split(block.type, block.data, path, len(verts))
        if fill is not None and (block.type in ("triangle", "quad") or block.type.startswith("polygon")):
            surface += s
        else:
            simplices += s
        if phys is not None and groups and block.type in ("vertex", "line", "triangle"):
            dim = dims[block.type]
            for cell, tag in zip(block.data, phys[b]):
                if (dim, int(tag)) in groups:
                    tags.append(sorted(int(x) for x in cell))
    body = {"vertices": verts}
    if simplices or fill is None:
        body["simplices"] = simplices
    if fill is not None:
        if not surface:
            raise MeshError(f"{path}: fill needs 2-D cells (a closed surface), and the mesh has none")
        body["fill"] = [dict(fill, surface=surface)]
    attrs = {}
    for name, data in (m.point_data or {}).items():
        if SKIP_DATA.match(name) or len(attrs) == 16:
            continue
        try:
            rows = [[float(x) for x in (r if hasattr(r, "__len__") else [r])] for r in data]
        except (TypeError, ValueError):
            continue
        if not rows or len(rows) != len(verts) or not 1 <= len(rows[0]) <= 16:
            continue
        if any(not math.isfinite(x) for r in rows for x in r):
            continue
        key = re.sub(r"[^A-Za-z0-9_-]", "_", name)[:48] or "attribute"
        attrs[key] = [r[0] for r in rows] if len(rows[0]) == 1 else rows
    if attrs:
        body["attributes"] = attrs
    if tags:
        uniq = []
        seen = set()
        for t in tags:
            if tuple(t) not in seen:
                seen.add(tuple(t))
                uniq.append(t)
        tags = uniq
    return body, (tags if groups else None)
