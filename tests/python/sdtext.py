"""Reader and writer for the line-oriented `sdlevel` text format (docs/TEXT_FORMAT.md).

Two kinds of files share the format:

* **input** files: `v x y z` vertices, `s i [j [k [l]]]` maximal simplices, optional
  `d t k` major-diagonal choices for tetrahedra;
* **output** of `build/sdlevel`: a `level L` header, `vertices N` followed by `v x y z TAG ...`
  lines (TAG is `I`, `V a`, `E a b` or `C o`), then counted blocks `points`, `edges`,
  `triangles`, `tetrahedra`, `octahedra`, and optionally `vclass`, `eclass` and `row` lines.

Everything is returned as plain dicts, lists and numpy arrays so tests can compare them with
the Python reference implementation without sharing any code with `core/`.  The parser is
strict: a malformed line raises `FormatError` with the line number, so a broken tool output
fails a test loudly instead of being half-read.
"""

import numpy as np


class FormatError(ValueError):
    """A line of a text-format file could not be parsed."""


def _strip(line):
    """Drop a `#` comment and surrounding blanks; return the remaining fields."""
    hash_at = line.find("#")
    if hash_at >= 0:
        line = line[:hash_at]
    return line.split()


def _ints(fields, where):
    try:
        return [int(f) for f in fields]
    except ValueError:
        raise FormatError(f"{where}: expected integers, got {' '.join(fields)!r}") from None


def _floats(fields, where):
    try:
        return [float(f) for f in fields]
    except ValueError:
        raise FormatError(f"{where}: expected numbers, got {' '.join(fields)!r}") from None


def _scalar(field):
    """A field of a class line: an int when it is one, else the word itself."""
    try:
        return int(field)
    except ValueError:
        return field


# --------------------------------------------------------------------------------------------
# input files


def parse_input_text(text, name="<input>"):
    """Parse an input complex.

    Returns a dict with
      verts     -- float array (nv, 3)
      simplices -- list of tuples, the `s` lines in order (1 to 4 indices each)
      tets      -- int array (nt, 4), the 4-index `s` lines in order
      diagonals -- dict {tet index: opposite-edge pair k in 0..2} from `d` lines
    """
    verts, simplices, diagonals = [], [], {}
    for lineno, raw in enumerate(text.splitlines(), 1):
        f = _strip(raw)
        if not f:
            continue
        where = f"{name}:{lineno}"
        key, rest = f[0], f[1:]
        if key == "v":
            if len(rest) != 3:
                raise FormatError(f"{where}: 'v' needs 3 coordinates")
            verts.append(_floats(rest, where))
        elif key == "s":
            if not 1 <= len(rest) <= 4:
                raise FormatError(f"{where}: 's' needs 1 to 4 vertex indices")
            simplices.append(tuple(_ints(rest, where)))
        elif key == "d":
            if len(rest) != 2:
                raise FormatError(f"{where}: 'd' needs a tetrahedron index and a pair 0..2")
            t, k = _ints(rest, where)
            if not 0 <= k <= 2:
                raise FormatError(f"{where}: diagonal pair {k} not in 0..2")
            diagonals[t] = k
        else:
            raise FormatError(f"{where}: unknown line type {key!r}")
    nv = len(verts)
    for s in simplices:
        if any(i < 0 or i >= nv for i in s):
            raise FormatError(f"{name}: simplex {s} refers to a vertex outside 0..{nv - 1}")
    tets = [s for s in simplices if len(s) == 4]
    for t in diagonals:
        if not 0 <= t < len(tets):
            raise FormatError(f"{name}: 'd' line names tetrahedron {t}, there are {len(tets)}")
    return {
        "verts": np.array(verts, dtype=float).reshape(-1, 3),
        "simplices": simplices,
        "tets": np.array(tets, dtype=np.int64).reshape(-1, 4),
        "diagonals": diagonals,
    }


def read_input(path):
    with open(path) as fh:
        return parse_input_text(fh.read(), str(path))


def write_input(path, verts, simplices, diagonals=None, comment=None):
    """Write an input complex: `v` lines with `%.17g` coordinates, then `s` lines.

    `simplices` is any iterable of index sequences (1 to 4 indices); `diagonals` an optional
    {tet index: k} dict written as `d` lines.
    """
    lines = []
    if comment:
        lines += ["# " + c for c in comment.splitlines()]
    for x in verts:
        if len(x) != 3:
            raise ValueError("vertices must have 3 coordinates")
        lines.append("v %.17g %.17g %.17g" % tuple(float(c) for c in x))
    for s in simplices:
        s = [int(i) for i in s]
        if not 1 <= len(s) <= 4:
            raise ValueError(f"simplex {s} must have 1 to 4 vertices")
        lines.append("s " + " ".join(str(i) for i in s))
    for t, k in sorted((diagonals or {}).items()):
        lines.append(f"d {int(t)} {int(k)}")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


# --------------------------------------------------------------------------------------------
# sdlevel output

# cell blocks: header word -> (line key, number of indices per line)
_BLOCKS = {
    "points": ("p", 1),
    "edges": ("e", 2),
    "triangles": ("t", 3),
    "tetrahedra": ("T", 4),
    "octahedra": ("O", 6),
}

# number of integer fields after the tag of an output `v` line
_TAG_ARITY = {"I": 0, "V": 1, "E": 2, "C": 1}


def parse_level_text(text, name="<sdlevel>"):
    """Parse the output of `sdlevel` for one level.

    Returns a dict with
      level      -- int
      verts      -- float array (N, 3)
      origins    -- list of tuples, e.g. ('I',), ('V', a), ('E', a, b), ('C', o); E pairs are
                    kept in the printed order
      points, edges, triangles, tetrahedra, octahedra
                 -- int arrays (n, 1|2|3|4|6); absent blocks are empty arrays
      vclass     -- {i: dict(family, boundary, nmtype, rule, valence)}
      eclass     -- {(a, b) sorted: dict(family, boundary, nmtype, rule, ringsize)}
      rows       -- {i: (cols int array, weights float array)}
    """
    lines = []
    for lineno, raw in enumerate(text.splitlines(), 1):
        f = _strip(raw)
        if f:
            lines.append((lineno, f))

    out = {
        "level": None,
        "verts": None,
        "origins": [],
        "vclass": {},
        "eclass": {},
        "rows": {},
    }
    for block, (_, width) in _BLOCKS.items():
        out[block] = np.zeros((0, width), dtype=np.int64)

    i = 0

    def take_counted(header, key, parse_one):
        """Read `header N` then N lines starting with `key`; return the parsed items."""
        nonlocal i
        lineno, f = lines[i]
        where = f"{name}:{lineno}"
        if len(f) != 2:
            raise FormatError(f"{where}: '{header}' needs one count")
        (n,) = _ints(f[1:], where)
        if n < 0:
            raise FormatError(f"{where}: negative count")
        i += 1
        items = []
        for _ in range(n):
            if i >= len(lines):
                raise FormatError(f"{name}: end of input inside the '{header}' block")
            lineno, f = lines[i]
            if f[0] != key:
                raise FormatError(f"{name}:{lineno}: expected a '{key}' line in '{header}'")
            items.append(parse_one(f[1:], f"{name}:{lineno}"))
            i += 1
        return items

    def parse_vertex(fields, where):
        if len(fields) < 4:
            raise FormatError(f"{where}: 'v' needs 3 coordinates and an origin tag")
        xyz = _floats(fields[:3], where)
        tag = fields[3]
        if tag not in _TAG_ARITY:
            raise FormatError(f"{where}: unknown origin tag {tag!r}")
        if len(fields) != 4 + _TAG_ARITY[tag]:
            raise FormatError(f"{where}: tag {tag} needs {_TAG_ARITY[tag]} indices")
        return xyz, (tag, *_ints(fields[4:], where))

    while i < len(lines):
        lineno, f = lines[i]
        where = f"{name}:{lineno}"
        key = f[0]
        if key == "level":
            if len(f) != 2:
                raise FormatError(f"{where}: 'level' needs one number")
            (out["level"],) = _ints(f[1:], where)
            i += 1
        elif key == "vertices":
            items = take_counted("vertices", "v", parse_vertex)
            out["verts"] = np.array([x for x, _ in items], dtype=float).reshape(-1, 3)
            out["origins"] = [o for _, o in items]
        elif key in _BLOCKS:
            line_key, width = _BLOCKS[key]

            def parse_cell(fields, w, width=width):
                if len(fields) != width:
                    raise FormatError(f"{w}: expected {width} indices")
                return _ints(fields, w)

            cells = take_counted(key, line_key, parse_cell)
            out[key] = np.array(cells, dtype=np.int64).reshape(-1, width)
        elif key == "vclass":
            if len(f) != 7:
                raise FormatError(f"{where}: 'vclass' needs 6 fields")
            (v,) = _ints(f[1:2], where)
            out["vclass"][v] = dict(zip(("family", "boundary", "nmtype", "rule", "valence"),
                                        (_scalar(x) for x in f[2:])))
            i += 1
        elif key == "eclass":
            if len(f) != 8:
                raise FormatError(f"{where}: 'eclass' needs 7 fields")
            a, b = _ints(f[1:3], where)
            out["eclass"][(min(a, b), max(a, b))] = dict(
                zip(("family", "boundary", "nmtype", "rule", "ringsize"),
                    (_scalar(x) for x in f[3:])))
            i += 1
        elif key == "row":
            if len(f) < 3:
                raise FormatError(f"{where}: 'row' needs an index and a count")
            r, n = _ints(f[1:3], where)
            rest = f[3:]
            if len(rest) != 2 * n:
                raise FormatError(f"{where}: row {r} announces {n} entries, has {len(rest) / 2}")
            cols = np.array(_ints(rest[0::2], where), dtype=np.int64)
            weights = np.array(_floats(rest[1::2], where), dtype=float)
            out["rows"][r] = (cols, weights)
            i += 1
        else:
            raise FormatError(f"{where}: unknown line type {key!r}")

    if out["level"] is None:
        raise FormatError(f"{name}: no 'level' line")
    if out["verts"] is None:
        raise FormatError(f"{name}: no 'vertices' block")
    nv = len(out["verts"])
    for block in _BLOCKS:
        cells = out[block]
        if cells.size and (cells.min() < 0 or cells.max() >= nv):
            raise FormatError(f"{name}: a cell in '{block}' refers to a vertex outside 0..{nv - 1}")
    return out


def read_level(path):
    with open(path) as fh:
        return parse_level_text(fh.read(), str(path))
