"""Reference implementation of ONE level of solid subdivision of a tetrahedral mesh.

This is a test oracle, written directly from docs/RULES.md (rules, splitting, conventions) and the solid-subdivision
paper (seeds/001, Chang & Qin, "Spline-based solid subdivision schemes over arbitrary
tetrahedral meshes"), independently of `core/`.  It favours being obviously right over being
fast: plain dicts and loops, meshes of a few thousand tetrahedra at most.

Scope: a pure tetrahedral control mesh (level 0, so no octahedra and no major diagonals are
involved in any vertex or edge rule) that is a 3-manifold with boundary.  Anything else
(non-manifold faces, edges or vertices, lower-dimensional simplices, unused vertices) is
refused with `NotManifoldError`; the non-manifold rules (000 Sec. 3.5) are out of scope.

Rules (docs/RULES.md `solid`; 001 Sec. 3.4-3.6):

* boundary face: a triangle that is a face of exactly one tetrahedron (docs/RULES.md "Classification").  A vertex
  or edge is on the boundary iff it is a vertex / an edge of a boundary face.  An edge whose two
  ends lie on the boundary but which is no edge of a boundary face (a chord) is interior.
* interior vertex x, k = |rho(x)|, rho(x) = every vertex joined to x by an edge (boundary
  neighbours included, docs/RULES.md / 001 Appendix B.1):
      9/16 x + 7/(16k) sum rho(x)                                   (001 eq. 3.7; 3.3 at k=14)
* interior edge [a, b], rho(e) = the other vertices of the tetrahedra containing the edge
  (the k vertices around it, 001 Fig. 17), k = |rho(e)|:
      k == 6: 10/32 (a+b) + 2/32 each                              (001 eq. 3.4)
      k == 4:  8/32 (a+b) + 4/32 each                              (001 eq. 3.5; docs/RULES.md "Conventions")
      else:    5/16 (a+b) + 3/(8k) each                            (001 eq. 3.8)
* boundary vertex (2-simplex rules on the boundary surface, docs/RULES.md; 001 Sec. 3.6,
  Fig. 14), m = number of neighbours along edges of boundary faces:
      (1 - m c) x + c sum(those neighbours),
      c = 3/16 if m == 3 else 3/(8m)                       ("warren", the default of docs/API.md)
      c = (1/m) (5/8 - (3/8 + cos(2 pi/m)/4)^2)            ("loop", 001 Fig. 14b)
* boundary edge [a, b] with opposite vertices c, d of its two boundary faces:
      3/8 (a+b) + 1/8 (c+d)                                         (001 Fig. 14a; Loop)

Splitting (docs/RULES.md "Splitting"): every tetrahedron becomes 4 corner tetrahedra and 1 octahedron, so
level 1 has V + E vertices, 4T tetrahedra and T octahedra.
"""

import math
from collections import defaultdict
from itertools import combinations

import numpy as np


class NotManifoldError(ValueError):
    """The input is not a manifold tetrahedral mesh with boundary."""


def _edge(a, b):
    return (a, b) if a < b else (b, a)


def _face(a, b, c):
    return tuple(sorted((a, b, c)))


def _connected(nodes, links):
    """True if the graph on `nodes` with undirected `links` (pairs) is connected."""
    nodes = set(nodes)
    if not nodes:
        return True
    adj = defaultdict(set)
    for u, v in links:
        adj[u].add(v)
        adj[v].add(u)
    start = next(iter(nodes))
    seen, stack = {start}, [start]
    while stack:
        u = stack.pop()
        for w in adj[u]:
            if w not in seen:
                seen.add(w)
                stack.append(w)
    return seen == nodes


def analyse(tets, nverts=None):
    """Derive faces, edges, boundary and rings of a tetrahedral mesh; refuse non-manifolds.

    Returns a dict:
      tets            -- list of 4-tuples (as given)
      vertices        -- sorted list of the vertices used
      edges           -- sorted list of edges (a < b)
      edge_tets       -- {edge: [tet indices]}
      face_tets       -- {face (sorted triple): [tet indices]}
      boundary_faces  -- set of faces in exactly one tetrahedron
      boundary_edges  -- set of edges of boundary faces
      boundary_verts  -- set of vertices of boundary faces
      vertex_nbrs     -- {v: set of vertices joined to v by an edge}          rho(x)
      boundary_nbrs   -- {v: set of neighbours along boundary edges} (boundary v only)
      edge_ring       -- {edge: set of the other vertices of its tetrahedra}  rho(e)
      edge_opposite   -- {boundary edge: (c, d) opposite vertices of its 2 boundary faces}
    """
    tets = [tuple(int(i) for i in t) for t in tets]
    if not tets:
        raise NotManifoldError("no tetrahedra")

    seen_tets = set()
    for ti, t in enumerate(tets):
        if len(t) != 4 or len(set(t)) != 4:
            raise NotManifoldError(f"tetrahedron {ti} {t} does not have 4 distinct vertices")
        if min(t) < 0 or (nverts is not None and max(t) >= nverts):
            raise NotManifoldError(f"tetrahedron {ti} {t} refers to a missing vertex")
        key = tuple(sorted(t))
        if key in seen_tets:
            raise NotManifoldError(f"tetrahedron {ti} {t} is listed twice")
        seen_tets.add(key)

    face_tets = defaultdict(list)
    edge_tets = defaultdict(list)
    vert_tets = defaultdict(list)
    for ti, t in enumerate(tets):
        for f in combinations(t, 3):
            face_tets[_face(*f)].append(ti)
        for a, b in combinations(t, 2):
            edge_tets[_edge(a, b)].append(ti)
        for v in t:
            vert_tets[v].append(ti)

    vertices = sorted(vert_tets)
    if nverts is not None and len(vertices) != nverts:
        unused = sorted(set(range(nverts)) - set(vertices))
        raise NotManifoldError(f"vertices {unused[:10]} belong to no tetrahedron")

    # A face of 3+ tetrahedra is non-manifold (type 2, docs/RULES.md "Classification").
    for f, ts in face_tets.items():
        if len(ts) > 2:
            raise NotManifoldError(f"face {f} is shared by {len(ts)} tetrahedra")
    boundary_faces = {f for f, ts in face_tets.items() if len(ts) == 1}

    edge_bfaces = defaultdict(list)
    for f in boundary_faces:
        for a, b in combinations(f, 2):
            edge_bfaces[_edge(a, b)].append(f)
    for e, fs in edge_bfaces.items():
        if len(fs) != 2:
            raise NotManifoldError(f"boundary edge {e} lies in {len(fs)} boundary faces, not 2")
    boundary_edges = set(edge_bfaces)
    boundary_verts = {v for f in boundary_faces for v in f}

    vertex_nbrs = defaultdict(set)
    for a, b in edge_tets:
        vertex_nbrs[a].add(b)
        vertex_nbrs[b].add(a)
    boundary_nbrs = defaultdict(set)
    for a, b in boundary_edges:
        boundary_nbrs[a].add(b)
        boundary_nbrs[b].add(a)

    # Vertex manifoldness: the tetrahedra around a vertex are connected through faces that
    # contain it, and around a boundary vertex the boundary faces form one umbrella (a single
    # cycle of link edges).  Either failure is a type-3 pinch (docs/RULES.md "Classification").
    vert_bfaces = defaultdict(list)
    for f in boundary_faces:
        for v in f:
            vert_bfaces[v].append(f)
    for v, ts in vert_tets.items():
        # faces containing v that join two of its tetrahedra
        by_face = defaultdict(list)
        for ti in ts:
            for f in combinations(tets[ti], 3):
                if v in f:
                    by_face[_face(*f)].append(ti)
        links = [tuple(x) for x in by_face.values() if len(x) == 2]
        if not _connected(ts, links):
            raise NotManifoldError(f"vertex {v} joins solids that meet only at it")
        if v in boundary_verts:
            link = [tuple(u for u in f if u != v) for f in vert_bfaces[v]]
            if not _connected(boundary_nbrs[v], link):
                raise NotManifoldError(f"boundary surface is pinched at vertex {v}")

    edge_ring = {}
    for e, ts in edge_tets.items():
        ring = set()
        for ti in ts:
            ring.update(u for u in tets[ti] if u not in e)
        edge_ring[e] = ring
        # Around a manifold edge its tetrahedra form a cycle (interior edge: k tets, k ring
        # vertices) or a fan (boundary edge: k tets, k+1 ring vertices).
        expect = len(ts) + (1 if e in boundary_edges else 0)
        if len(ring) != expect:
            raise NotManifoldError(f"edge {e}: {len(ts)} tetrahedra but {len(ring)} ring vertices")

    edge_opposite = {}
    for e, fs in edge_bfaces.items():
        edge_opposite[e] = tuple(next(u for u in f if u not in e) for f in fs)

    return {
        "tets": tets,
        "vertices": vertices,
        "edges": sorted(edge_tets),
        "edge_tets": dict(edge_tets),
        "face_tets": dict(face_tets),
        "boundary_faces": boundary_faces,
        "boundary_edges": boundary_edges,
        "boundary_verts": boundary_verts,
        "vertex_nbrs": dict(vertex_nbrs),
        "boundary_nbrs": dict(boundary_nbrs),
        "edge_ring": edge_ring,
        "edge_opposite": edge_opposite,
    }


def loop_weight(m, weights="warren"):
    """Weight c of each of the m surface neighbours of a surface vertex (docs/RULES.md `loop`)."""
    if m < 3:
        raise NotManifoldError(f"surface vertex with {m} neighbours")
    if weights == "warren":
        return 3.0 / 16.0 if m == 3 else 3.0 / (8.0 * m)
    if weights == "loop":
        return (5.0 / 8.0 - (3.0 / 8.0 + math.cos(2.0 * math.pi / m) / 4.0) ** 2) / m
    raise ValueError(f"unknown surface weights {weights!r}")


def level1_stencils(tets, weights="warren", nverts=None, mesh=None):
    """The rows of the level-0 -> level-1 subdivision matrix, as sparse dicts.

    Returns (vertex_stencils, edge_stencils, mesh):
      vertex_stencils -- {v: {u: weight}}       the new position of vertex v
      edge_stencils   -- {(a, b): {u: weight}}  the new point on edge a-b (a < b)
      mesh            -- the `analyse` result
    """
    if mesh is None:
        mesh = analyse(tets, nverts)
    vstencil = {}
    for v in mesh["vertices"]:
        row = defaultdict(float)
        if v in mesh["boundary_verts"]:
            # 2-simplex rule on the boundary surface (docs/RULES.md; 001 Sec. 3.6, Fig. 14b)
            nb = mesh["boundary_nbrs"][v]
            c = loop_weight(len(nb), weights)
            row[v] += 1.0 - len(nb) * c
            for u in nb:
                row[u] += c
        else:
            # 3-simplex vertex rule, 001 eq. 3.7: 9/16 x + 7/(16k) sum rho(x)
            nb = mesh["vertex_nbrs"][v]
            k = len(nb)
            row[v] += 9.0 / 16.0
            for u in nb:
                row[u] += 7.0 / (16.0 * k)
        vstencil[v] = dict(row)

    estencil = {}
    for e in mesh["edges"]:
        a, b = e
        row = defaultdict(float)
        if e in mesh["boundary_edges"]:
            # Loop edge rule on the boundary surface: 3/8 (a+b) + 1/8 (c+d)  (001 Fig. 14a)
            c, d = mesh["edge_opposite"][e]
            row[a] += 3.0 / 8.0
            row[b] += 3.0 / 8.0
            row[c] += 1.0 / 8.0
            row[d] += 1.0 / 8.0
        else:
            # 3-simplex edge rules; interior edges include chords between boundary vertices
            ring = mesh["edge_ring"][e]
            k = len(ring)
            if k == 6:  # 001 eq. 3.4
                wa, wr = 10.0 / 32.0, 2.0 / 32.0
            elif k == 4:  # 001 eq. 3.5 (docs/RULES.md "Conventions": not the generic 5/16, 3/32)
                wa, wr = 8.0 / 32.0, 4.0 / 32.0
            else:  # 001 eq. 3.8
                wa, wr = 5.0 / 16.0, 3.0 / (8.0 * k)
            row[a] += wa
            row[b] += wa
            for u in ring:
                row[u] += wr
        estencil[e] = dict(row)
    return vstencil, estencil, mesh


def apply_stencil(row, verts):
    """Sum of weight * verts[u] over a stencil row (verts: array (n, d))."""
    acc = np.zeros(verts.shape[1:], dtype=float)
    for u, w in row.items():
        acc = acc + w * verts[u]
    return acc


def level1_counts(tets):
    """Expected level-1 element counts of a pure tetrahedral level 0 (docs/RULES.md "Splitting")."""
    tets = [tuple(t) for t in tets]
    nv = len({v for t in tets for v in t})
    ne = len({_edge(a, b) for t in tets for a, b in combinations(t, 2)})
    nt = len(tets)
    return {
        "vertices": nv + ne,      # one vertex point per vertex, one edge point per edge
        "points": 0,
        "edges": 0,
        "triangles": 0,           # all triangles are faces of solids
        "tetrahedra": 4 * nt,     # 4 corner tetrahedra per tetrahedron
        "octahedra": nt,          # 1 central octahedron per tetrahedron
    }


def level1_tets(verts, tets, weights="warren"):
    """One level of solid subdivision of a tetrahedral mesh (see the module comment).

    verts: array (n, d) -- positions, or any per-vertex attribute (d columns)
    tets:  array (T, 4) of vertex indices

    Returns a dict:
      vertex_points   -- {v: array (d,)}
      edge_points     -- {(a, b) with a < b: array (d,)}
      vertex_stencils, edge_stencils -- the matrix rows ({u: weight})
      counts          -- level1_counts(tets)
      mesh            -- the `analyse` result (boundary sets, rings, ...)
    """
    verts = np.asarray(verts, dtype=float)
    if verts.ndim == 1:
        verts = verts[:, None]
    vst, est, mesh = level1_stencils(tets, weights, nverts=len(verts))
    return {
        "vertex_points": {v: apply_stencil(row, verts) for v, row in vst.items()},
        "edge_points": {e: apply_stencil(row, verts) for e, row in est.items()},
        "vertex_stencils": vst,
        "edge_stencils": est,
        "counts": level1_counts(mesh["tets"]),
        "mesh": mesh,
    }
