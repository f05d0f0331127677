"""The web front end served at / (web/, built by web/build.mjs into build/web and embedded).

HTTP: the page and its content-hashed bundles are served with their content types, index.html is
revalidated (no-cache + ETag, 304), the bundles are immutable.

Browser: tests/web/browser_test.mjs drives Debian's chromium (headless, playwright-core) against
a daemon started here the way `make run` starts it (default flags, another port). It prints one
JSON report; each of its checks is one test below, so a missing check fails too. Screenshots go
to test-output/web/.

Readers: web/src/meshfile.js under node reads STL and Gmsh files meshio wrote into what meshio
reads back.
"""
import json
import os
import re
import shutil
import subprocess

import pytest
import requests

from conftest import REPO
from daemon import Daemon

CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")
OUTDIR = REPO / "test-output" / "web"
BROWSER_TEST = REPO / "tests" / "web" / "browser_test.mjs"

# The checks browser_test.mjs reports, in its order.
CHECKS = [
    "first_load",        # an example at level 2 within seconds, with a hint, no interaction
    "messages_coalesce",  # the same message again counts up on the one shown
    "canvas_a11y",       # the view: role img, a current label, tab order, arrow keys pan
    "examples",          # the three built-in examples are accepted and drawn
    "level_slider",      # the slider (keyboard) moves to 0 and back to 2
    "canvas_geometry",   # non-blank pixels (screenshot and read back)
    "stats_shown",       # the panel shows the level's stats as GET /levels/2/stats has them
    "slice_colour",      # the slice in its own colour (not the solids')
    "cross_section",     # slice on (primitive present, picture changes), moved, off
    "surface_inside",    # with the cut on, the embedded-surface tool tags a triangle inside the solid
    "show_hide",         # solid boundary and cage toggles
    "attribute_colour",  # colormap=NAME:min:max and its legend
    "gltf_loader",       # the GLB in three.js's GLTFLoader: node/mesh per part, one POSITION, extras, linear COLOR_0
    "edge_occlusion",    # a control edge inside the solid is not picked by a click (hidden), unless the boundary is hidden
    "crease_tag",        # clicking a control edge with the crease tool: PUT /tags 200, tagged
    "crease_colour",     # ... its rule turns to the crease's (curve) and so does its colour
    "crease_sharpness",  # the same edge at sharpness 0.5: one PUT /tags keeping the other tags; level changes
    "sharpness_colour",  # colour by sharpness: that edge in the ramp colour, untagged edges grey, a legend
    "crease_method",     # the crease-method selector: PUT /rules crease_method chaikin, and back
    "crease_angle",      # creases over 40° / 100°: the edges tagged = those computed in the test; unticking restores
    "nonmanifold_rule",  # G1 for a vertex: 501 shown in words (until issue 4), else its colour
    "solid_scheme",      # a rule the daemon has (averaged) changes the level
    "drag_point",        # dragging a control point: version advances, GLB and picture change
    "undo_redo",         # Ctrl+Z puts it back exactly, Redo moves it again
    "slice_follows_edits",  # the cut = the daemon's after a drag, an undo, a redo, an edit elsewhere
    "level_back",        # a level that cannot be fetched is said; the slider goes back to the level drawn
    "embed_model",       # an OBJ embedded in the solid follows a drag by its deltas, drawn = the daemon's
    "second_tab_new_model",  # a model loaded in one tab is taken whole by the other (points, attributes, no undo)
    "file_open",         # an OBJ from disk
    "file_errors",       # a broken file and a refused one are explained
    "file_stl_msh",      # STL and Gmsh .msh from disk; the model selector shows the file
    "level_note",        # the note under the slider says why it stops (the cell limit)
    "keyboard_files",    # Open file… and Embed a model… reached by Tab; Space opens the file chooser
    "session_recovery",  # an expired session is replaced with the same model, and the user told
    "session_recovery_drag",  # the same when the 404 comes to a drag: the new level drawn, = refetch
    "default_rules",     # the default-rule list is G2, G1 (N1/N2 only as overrides of one simplex)
    "occlusion",         # 10³ cubes at level 3: an interior point is not picked nor drawn, unless asked
    "live_drag_1m",      # a drag on >= 1 M cells: PATCH + delta only, one PATCH in flight, buffers = refetch
    "second_tab",        # a second tab on the session follows by events + deltas, buffers = refetch
    "delta_410",         # a change behind the page's back: 412, 410, the level fetched again, = refetch
    "level_moves",       # level-3 handles; a drag PATCHes "level": 3; buffers = refetch
    "keyboard_move",     # a point moved by typing its number and coordinates; delta; Ctrl+Z
    "keyboard_move_loading",  # typed while the edit level's points load: nothing sent; then refilled
    "second_tab_close",  # closing the tab that joined leaves the session open for the first
    "tab_reload",        # a reload opens the tab's session again: same model, edits, offsets, TTL back to 1 h
    "tab_duplicate",     # a duplicated tab joins the session without owning it; closing it keeps the TTL
    "tab_close_ttl",     # a closed tab gives its own session the short TTL (PATCH ttl_s 120 at pagehide)
    "reload_embedded",   # a reload draws the session's embedded model again, = the daemon's
    "second_tab_embedded",  # a tab opened by the link draws it, and takes it away when the first removes it
    "link_replaced",     # a link's tab whose session went: a session of its own, the address follows, a reload opens it
    "bfcache_gone",      # back from the back/forward cache with the session gone: replaced, said as info
    "events_refused",    # an event stream answered 404 (session gone) / 429: replaced and said / said
    "console_clean",     # no console errors but the refusals the test provokes
]


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    d.stop()


@pytest.fixture(scope="module")
def report(daemon):
    assert os.path.exists(CHROMIUM), f"{CHROMIUM} missing: apt-get install chromium (tools/packages.txt)"
    assert (REPO / "tests" / "web" / "node_modules" / "playwright-core").is_dir(), \
        "playwright-core missing: run tools/deps.sh (npm ci in tests/web)"
    if OUTDIR.exists():
        shutil.rmtree(OUTDIR)
    r = subprocess.run(["node", str(BROWSER_TEST), daemon.url + "/", str(OUTDIR)], cwd=REPO,
                       capture_output=True, encoding="utf-8", timeout=600)
    lines = r.stdout.strip().splitlines()
    assert lines and lines[-1].startswith("{"), \
        f"browser test did not finish (exit {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    (OUTDIR / "report.txt").write_text(r.stdout + r.stderr, encoding="utf-8")
    return {c["name"]: c for c in json.loads(lines[-1])["checks"]}


@pytest.mark.parametrize("name", CHECKS)
def test_browser(report, name):
    assert name in report, f"check {name} was not reached (see test-output/web/report.txt)"
    assert report[name]["ok"], report[name]["detail"]


def test_browser_reports_only_known_checks(report):
    assert sorted(report) == sorted(CHECKS)


# ---- the assets over HTTP --------------------------------------------------------------------

def bundles(html):
    return re.findall(r'(?:src|href)="(/assets/app-[A-Za-z0-9]+\.(?:js|css))"', html)


def test_index_html(daemon):
    r = requests.get(daemon.url + "/")
    assert r.status_code == 200
    assert r.headers["Content-Type"] == "text/html;charset=utf-8"
    assert r.headers["Cache-Control"] == "no-cache"
    assert re.fullmatch(r'"[0-9a-f]{16}"', r.headers["ETag"])
    assert r.headers["X-Content-Type-Options"] == "nosniff"
    names = bundles(r.text)
    assert sorted(n.rsplit(".", 1)[1] for n in names) == ["css", "js"]
    assert "%APP_" not in r.text  # the build filled the template in


def test_index_revalidates_with_etag(daemon):
    tag = requests.get(daemon.url + "/").headers["ETag"]
    r = requests.get(daemon.url + "/", headers={"If-None-Match": tag})
    assert r.status_code == 304 and r.content == b"" and r.headers["ETag"] == tag
    assert r.headers["Cache-Control"] == "no-cache"
    r = requests.get(daemon.url + "/", headers={"If-None-Match": '"0000000000000000"'})
    assert r.status_code == 200 and r.content


def test_bundles_are_immutable_with_their_types(daemon):
    html = requests.get(daemon.url + "/").text
    types = {"js": "text/javascript;charset=utf-8", "css": "text/css;charset=utf-8"}
    for name in bundles(html):
        r = requests.get(daemon.url + name)
        assert r.status_code == 200, name
        assert r.headers["Content-Type"] == types[name.rsplit(".", 1)[1]]
        assert r.headers["Cache-Control"] == "public,max-age=31536000,immutable"
        assert int(r.headers["Content-Length"]) == len(r.content) > 0
        h = requests.head(daemon.url + name)
        assert h.status_code == 200 and h.headers["Content-Type"] == r.headers["Content-Type"]
    # the bundle is three.js and the app, built from web/ (no CDN, no source maps)
    js = requests.get(daemon.url + [n for n in bundles(html) if n.endswith(".js")][0]).text
    assert "window.subdivd" in js or "subdivd=" in js
    assert "sourceMappingURL" not in js


def test_unknown_asset_and_stale_bundle_are_404(daemon):
    r = requests.get(daemon.url + "/assets/app-STALE.js")
    assert r.status_code == 404
    assert r.headers["Content-Type"] == "application/problem+json"


def test_openapi_is_revalidated(daemon):
    r = requests.get(daemon.url + "/v1/openapi.json")
    assert r.status_code == 200 and r.headers["Cache-Control"] == "no-cache"
    assert requests.get(daemon.url + "/v1/openapi.json",
                        headers={"If-None-Match": r.headers["ETag"]}).status_code == 304


# ---- the page's mesh file readers (web/src/meshfile.js) against meshio ------------------------

READ_MESH = """
import fs from 'node:fs';
import { parseMeshFile } from '%s';
const b = fs.readFileSync(process.argv[2]);
const body = parseMeshFile(process.argv[2], b.buffer.slice(b.byteOffset, b.byteOffset + b.length));
console.log(JSON.stringify(body));
"""


@pytest.mark.parametrize("fmt,ext,opts", [("stl", "stl", {"binary": True}), ("stl", "stl", {"binary": False}),
                                          ("gmsh", "msh", {"binary": False}),
                                          ("gmsh22", "msh", {"binary": False})])
def test_meshfile_readers_agree_with_meshio(tmp_path, fmt, ext, opts):
    """STL (binary, ASCII) and Gmsh .msh (4.1, 2.2 ASCII) written by meshio are read by the page's
    reader into the points and cells meshio reads back (STL: equal points merged by both)."""
    import meshio
    import numpy as np
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0.5]], dtype=float)
    if fmt == "stl":
        cells = [("triangle", np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 4]]))]
    elif fmt == "gmsh":  # meshio writes 4.1 for one cell type without entity data
        cells = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]
    else:
        cells = [("tetra", np.array([[0, 1, 2, 3]])), ("triangle", np.array([[1, 2, 4]])),
                 ("line", np.array([[3, 4]])), ("vertex", np.array([[4]]))]
    f = tmp_path / f"m.{ext}"
    meshio.write(str(f), meshio.Mesh(pts, cells), file_format=fmt, **opts)
    script = tmp_path / "read.mjs"
    script.write_text(READ_MESH % (REPO / "web" / "src" / "meshfile.js").as_uri())
    r = subprocess.run(["node", str(script), str(f)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    body = json.loads(r.stdout)
    m = meshio.read(str(f))
    np.testing.assert_allclose(np.array(body["vertices"]), m.points, rtol=1e-6)
    want = sorted(tuple(int(i) for i in c) for block in m.cells for c in block.data)
    assert sorted(tuple(s) for s in body["simplices"]) == want


def test_meshfile_readers_refuse_what_meshes_py_refuses(tmp_path):
    """Files the page read wrongly without a word, as the CLI's reader reads them: an OFF counts
    line without the edge count (the first vertex's x was taken for it), an OBJ index "3x" or
    "1.5" (parseInt read 3 and 1), an ASCII STL cut short (the triangles before passed for the mesh)."""
    script = tmp_path / "read.mjs"
    script.write_text(READ_MESH % (REPO / "web" / "src" / "meshfile.js").as_uri())
    cases = {"a.off": "OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "b.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3x\n",
             "c.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1.5 2 3\n",
             "d.stl": "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                      "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"}
    out = {}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        r = subprocess.run(["node", str(script), str(tmp_path / name)], capture_output=True, text=True, timeout=60)
        out[name] = r.stdout if r.returncode == 0 else r.stderr
    assert json.loads(out["a.off"]) == {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "simplices": [[0, 1, 2]]}
    assert 'line 4: bad vertex reference "3x"' in out["b.obj"] and '"1.5"' in out["c.obj"]
    assert "line 11: the file ends inside a facet" in out["d.stl"]
