"""Black-box tests of every v1 endpoint (docs/API.md) against the real daemon on loopback.

Expected values come from the papers' split table, from the independent text tool `sdlevel`
(a separate client of core/ with its own output path), or from counting in Python — never from
the daemon's own earlier answers."""
import datetime
import json
import pathlib
import re
import signal
import subprocess
import threading
import time

import numpy as np
import pytest
import requests

import sdtext
from conftest import REPO, SDLEVEL, make_mesh_file
from daemon import SLOW, SUBDIVD, Daemon, Session, complex_from_text

MIXED = REPO / "examples" / "mixed.txt"
CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"
TET = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0, "the daemon did not exit cleanly on SIGTERM:\n" + "\n".join(d.log_lines[-20:])


def sdlevel(path, level, *opts):
    out = subprocess.run([str(SDLEVEL), "-l", str(level), *opts, str(path)], check=True,
                         capture_output=True, text=True).stdout
    return sdtext.parse_level_text(out)


# ---- service endpoints ------------------------------------------------------------------------

def test_health_ready(daemon):
    for path in ("/healthz", "/livez"):
        r = requests.get(daemon.url + path)
        assert r.status_code == 200 and r.json() == {"status": "ok"}
    r = requests.get(daemon.url + "/readyz")
    assert r.status_code == 200 and r.json()["status"] == "ready"
    # the members the OpenAPI document declares, no more, no fewer
    doc = json.loads((REPO / "api" / "openapi.json").read_text(encoding="utf-8"))
    schema = doc["paths"]["/readyz"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    j = r.json()
    assert set(j) == set(schema["properties"]) == set(schema["required"])
    assert set(j["memory"]) == set(schema["properties"]["memory"]["properties"])
    assert j["store"] == "memory"   # the default --store


def test_metrics_exposition(daemon):
    requests.get(daemon.url + "/healthz")
    requests.get(daemon.url + "/nowhere")
    r = requests.get(daemon.url + "/metrics")
    assert r.status_code == 200
    assert r.headers["Content-Type"].startswith("text/plain; version=0.0.4")
    text = r.text
    assert text.endswith("\n")
    for name, kind in [("subdivd_requests_total", "counter"),
                       ("subdivd_request_duration_seconds", "histogram"),
                       ("subdivd_sessions", "gauge"), ("subdivd_cached_cells", "gauge"),
                       ("subdivd_api_bytes", "gauge"),
                       ("subdivd_streamed_bytes_total", "counter")]:
        assert f"# TYPE {name} {kind}" in text
    assert re.search(r'subdivd_requests_total\{route="/healthz",method="GET",status="200"\} [1-9]', text)
    assert re.search(r'subdivd_requests_total\{route="unknown",method="GET",status="404"\} [1-9]', text)
    # one latency histogram per route, method and status: cumulative buckets ending at the count
    series = set(re.findall(r'^subdivd_request_duration_seconds_count\{([^}]*)\} \d+$', text, re.M))
    assert 'route="/healthz",method="GET",status="200"' in series
    for labels in series:
        buckets = [int(v) for v in re.findall(
            r'^subdivd_request_duration_seconds_bucket\{' + re.escape(labels) + r',le="[^"]+"\} (\d+)$',
            text, re.M)]
        assert buckets == sorted(buckets), "histogram buckets must be cumulative"
        count = int(re.search(r'^subdivd_request_duration_seconds_count\{' + re.escape(labels)
                              + r'\} (\d+)$', text, re.M).group(1))
        assert buckets[-1] == count and re.search(re.escape(labels) + r',le="\+Inf"', text)


def test_metrics_api_bytes_follow_sessions(daemon):
    """subdivd_api_bytes counts what api/ and server/ hold (api/mem.h): a session with a complex
    and a cached glTF level holds some, and deleting it gives them back."""
    def api_bytes():
        text = requests.get(daemon.url + "/metrics").text
        return int(re.search(r"^subdivd_api_bytes (\d+)$", text, re.M).group(1))
    before = api_bytes()
    assert before > 0
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    assert s.level(2).status_code == 200
    held = api_bytes()
    assert held > before
    assert s.delete().status_code == 204
    assert api_bytes() < held


def test_openapi_matches_routes(daemon):
    r = requests.get(daemon.url + "/v1/openapi.json")
    assert r.status_code == 200 and r.headers["Content-Type"].startswith("application/json")
    doc = r.json()
    assert doc == json.loads((REPO / "api" / "openapi.json").read_text(encoding="utf-8"))
    assert doc["openapi"] == "3.1.0"
    routes = subprocess.run([str(SUBDIVD), "--list-routes"], check=True, capture_output=True,
                            text=True).stdout.split("\n")
    served = {tuple(l.split(" ", 1)) for l in routes if l}
    documented = {(m.upper(), p) for p, item in doc["paths"].items() for m in item
                  if m in ("get", "put", "post", "patch", "delete")}
    assert served == documented
    # every $ref resolves
    def refs(x):
        if isinstance(x, dict):
            for k, v in x.items():
                if k == "$ref":
                    yield v
                else:
                    yield from refs(v)
        elif isinstance(x, list):
            for v in x:
                yield from refs(v)
    for ref in refs(doc):
        node = doc
        for part in ref.lstrip("#/").split("/"):
            node = node[part]


def test_front_page(daemon):
    r = requests.get(daemon.url + "/")
    assert r.status_code == 200 and r.headers["Content-Type"].startswith("text/html")
    assert "/v1/openapi.json" in r.text


# ---- sessions ---------------------------------------------------------------------------------

def test_session_lifecycle(daemon):
    r = requests.post(daemon.url + "/v1/sessions", json={"ttl_s": 600})
    assert r.status_code == 201
    j = r.json()
    assert re.fullmatch(r"[0-9a-f]{32}", j["id"]) and len(j["token"]) >= 43
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", j["expires_at"])
    assert r.headers["Location"] == f"/v1/sessions/{j['id']}"
    auth = {"Authorization": f"Bearer {j['token']}"}
    g = requests.get(f"{daemon.url}/v1/sessions/{j['id']}", headers=auth)
    assert g.status_code == 200
    s = g.json()
    assert s["id"] == j["id"] and s["version"] == 0 and s["levels_cached"] == 0
    assert s["summary"] == {} and s["progress"] is None
    # an empty body (no JSON at all) also creates a session
    r2 = requests.post(daemon.url + "/v1/sessions")
    assert r2.status_code == 201 and r2.json()["id"] != j["id"]
    d = requests.delete(f"{daemon.url}/v1/sessions/{j['id']}", headers=auth)
    assert d.status_code == 204 and d.content == b""
    assert requests.get(f"{daemon.url}/v1/sessions/{j['id']}", headers=auth).status_code == 404


def test_session_answers_carry_the_version_as_etag_from_0(daemon):
    """Every answer that carries the session's version sends it as a strong ETag (docs/API.md,
    the OpenAPI document's ETag headers), a new session's version 0 too: POST /v1/sessions (and
    an import, at the version it continues from), GET and PATCH /v1/sessions/{id}, GET /export."""
    r = requests.post(daemon.url + "/v1/sessions", json={})
    assert r.status_code == 201 and r.json()["version"] == 0
    assert r.headers.get("ETag") == '"0"'
    base = f"{daemon.url}/v1/sessions/{r.json()['id']}"
    auth = {"Authorization": f"Bearer {r.json()['token']}"}
    for method, path, body in (("GET", "", None), ("PATCH", "", {"ttl_s": 300}),
                               ("GET", "/export", None)):
        a = requests.request(method, base + path, headers=auth, json=body)
        assert a.status_code == 200 and a.json()["version"] == 0, a.text
        assert a.headers.get("ETag") == '"0"', (method, path, dict(a.headers))
    assert requests.put(base + "/complex", headers={**auth, "If-Match": '"0"'},
                        json=TET).status_code == 200
    doc = requests.get(base + "/export", headers=auth)
    assert doc.headers["ETag"] == '"1"'
    i = requests.post(daemon.url + "/v1/sessions", json={"import": doc.json()})
    assert i.status_code == 201 and i.headers["ETag"] == '"1"' and i.json()["version"] == 1


def test_ttl_expiry():
    d = Daemon()
    try:
        s = Session(d, ttl_s=1)
        assert s.req("GET").status_code == 200
        time.sleep(2.6)
        assert s.req("GET").status_code == 404
    finally:
        assert d.stop() == 0


def test_a_session_ttl_can_be_changed():
    """PATCH /v1/sessions/{id} {"ttl_s"}: a new idle TTL from now, capped at --max-ttl like
    POST's, validated like POST's; not a change of the content (no version, no If-Match)."""
    d = Daemon("--max-ttl", "100")
    try:
        s = Session(d, ttl_s=60)
        patch = lambda body, **kw: s.req("PATCH", json=body, **kw)
        r = patch({"ttl_s": 1000})
        assert r.status_code == 200, r.text
        j = r.json()
        assert j["id"] == s.id and j["ttl_s"] == 100 and j["version"] == 0   # capped
        left = (datetime.datetime.strptime(j["expires_at"], "%Y-%m-%dT%H:%M:%SZ")
                .replace(tzinfo=datetime.timezone.utc).timestamp() - time.time())
        assert 97 <= left <= 101, left
        for body, status, ptr in (({}, 400, "/ttl_s"), ({"ttl_s": 0}, 422, "/ttl_s"),
                                  ({"ttl_s": 10 ** 12}, 422, "/ttl_s"), ({"ttl_s": "5"}, 400, "/ttl_s"),
                                  ({"ttl_s": 5, "x": 1}, 400, "/x")):
            r = patch(body)
            assert r.status_code == status, (body, r.text)
            assert r.headers["Content-Type"] == "application/problem+json"
            assert [e["pointer"] for e in r.json()["errors"]] == [ptr], (body, r.text)
        assert patch({"ttl_s": 5}, headers={"Authorization": "Bearer nope"}).status_code == 401
        assert s.req("GET").json()["version"] == 0            # nothing of the content changed
        # shortened: the session goes after the new TTL of idleness, not the old one
        assert patch({"ttl_s": 1}).json()["ttl_s"] == 1
        time.sleep(2.6)
        assert s.req("GET").status_code == 404
        assert patch({"ttl_s": 60}).status_code == 404
    finally:
        assert d.stop() == 0


def test_tokens_are_per_session(daemon):
    a, b = Session(daemon), Session(daemon)
    r = requests.get(a.base, headers=b.auth)
    assert r.status_code == 401 and "Bearer" in r.headers["WWW-Authenticate"]


def test_no_auth_mode():
    d = Daemon("--no-auth")
    try:
        j = requests.post(d.url + "/v1/sessions").json()
        assert requests.get(f"{d.url}/v1/sessions/{j['id']}").status_code == 200
    finally:
        assert d.stop() == 0


# ---- complex, summary, classes --------------------------------------------------------------

def faces_of(simplices):
    """Every face of the posted simplices, by dimension (independent counting)."""
    from itertools import combinations
    faces = [set() for _ in range(4)]
    for s in simplices:
        for k in range(1, len(s) + 1):
            for f in combinations(sorted(s), k):
                faces[k - 1].add(f)
    return faces


@pytest.mark.parametrize("mesh", [MIXED, CUBE])
def test_put_complex_summary(daemon, mesh):
    body = complex_from_text(mesh)
    s = Session(daemon)
    r = s.put_complex(body)
    assert r.status_code == 200, r.text
    j = r.json()
    assert j["version"] == 1 and r.headers["ETag"] == '"1"'
    faces = faces_of(body["simplices"])
    sm = j["summary"]
    assert sm["vertices"] == len(body["vertices"])
    assert sm["edges"] == len(faces[1]) and sm["faces"] == len(faces[2])
    # maximal simplices per dimension: not a face of another posted simplex
    maximal = [0, 0, 0, 0]
    for dim in range(4):
        for f in faces[dim]:
            if not any(set(f) < set(g) for g in faces[dim + 1] if dim < 3) if dim < 3 else True:
                maximal[dim] += 1
    assert [sm["simplices"][str(k)] for k in range(4)] == maximal
    g = s.req("GET")
    assert g.json()["version"] == 1 and g.json()["summary"] == sm and g.json()["levels_cached"] >= 1


def test_get_complex_classes(daemon):
    body = complex_from_text(MIXED)
    body["attributes"] = {"temp": [float(i) for i in range(8)],
                          "vel": [[i, 0, 1] for i in range(8)]}
    s = Session(daemon)
    assert s.req("GET", "/complex").status_code == 409
    assert s.put_complex(body).status_code == 200
    r = s.req("GET", "/complex")
    assert r.status_code == 200 and r.headers["ETag"] == '"1"'
    j = r.json()
    assert j["vertices"] == body["vertices"] and j["simplices"] == body["simplices"]
    assert j["attributes"]["temp"] == body["attributes"]["temp"]
    assert j["attributes"]["vel"] == body["attributes"]["vel"]
    ref = sdlevel(MIXED, 0, "--classes")
    cv = j["classes"]["vertices"]
    assert len(cv) == len(ref["verts"])
    for i, c in enumerate(cv):
        assert c["rule"] == ref["vclass"][i]["rule"]
        assert c["nonmanifold"] == ref["vclass"][i]["nmtype"]
        assert c["singular"] is False
    edges = {tuple(sorted(e["vertices"])): e for e in j["classes"]["edges"]}
    assert set(edges) == set(ref["eclass"])
    for k, e in edges.items():
        assert e["rule"] == ref["eclass"][k]["rule"]
    # the isolated point is a corner, the curve's free end too (000 Sec. 3.1: 0-mask at ends)
    assert cv[7]["rule"] == "corner" and cv[7]["family"] == [0]
    assert cv[6]["rule"] == "corner" and cv[5]["rule"] == "curve"
    assert j["rules"]["solid_scheme"] == "box" and j["tags"] == {"singular": []}


def test_valence_counts_the_neighbours_the_rule_reads(daemon):
    """docs/API.md: `valence` is the number of neighbours a point's rule reads — a surface
    boundary vertex's two boundary neighbours whatever its interior ones, a corner none, an
    interior Loop vertex its whole 1-ring."""
    # a 3x3 grid of points (a fan of 8 triangles around the centre 4), corner tag on 0
    v = [[x, y, 0] for y in range(3) for x in range(3)]
    t = [[0, 1, 4], [1, 2, 4], [2, 5, 4], [5, 8, 4], [8, 7, 4], [7, 6, 4], [6, 3, 4], [3, 0, 4]]
    s = Session(daemon)
    assert s.put_complex({"vertices": v, "simplices": t}).status_code == 200
    assert s.req("PUT", "/tags", json={"singular": [[0]]}).status_code == 200
    cv = s.req("GET", "/complex").json()["classes"]["vertices"]
    assert (cv[4]["rule"], cv[4]["valence"]) == ("loop", 8)
    assert (cv[0]["rule"], cv[0]["valence"]) == ("corner", 0)
    for i in (1, 2, 3, 5, 6, 7, 8):          # 1, 3, 5, 7 have 3 neighbours, one interior
        assert (cv[i]["rule"], cv[i]["valence"]) == ("loop-boundary", 2), (i, cv[i])


def test_rules_change_levels(daemon):
    body = complex_from_text(CUBE)
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    box = s.level(1, format="json").json()
    r = s.req("PUT", "/rules", json={"solid_scheme": "averaged", "surface_weights": "loop"})
    assert r.status_code == 200 and r.json()["version"] == 2 and r.headers["ETag"] == '"2"'
    avg = s.level(1, format="json").json()
    assert avg["version"] == 2 and box["version"] == 1
    ref = sdlevel(CUBE, 1, "-s", "averaged", "-w", "loop")
    np.testing.assert_allclose(np.array(avg["vertices"]), ref["verts"], rtol=0, atol=1e-12)
    ref_box = sdlevel(CUBE, 1)
    np.testing.assert_allclose(np.array(box["vertices"]), ref_box["verts"], rtol=0, atol=1e-12)
    assert np.abs(np.array(avg["vertices"]) - np.array(box["vertices"])).max() > 1e-6
    # rules survive a new complex
    assert s.put_complex(body).status_code == 200
    again = s.level(1, format="json").json()
    np.testing.assert_allclose(np.array(again["vertices"]), ref["verts"], rtol=0, atol=1e-12)
    assert s.req("GET", "/complex").json()["rules"]["solid_scheme"] == "averaged"


def test_empty_tags_accepted(daemon):
    s = Session(daemon)
    assert s.put_complex(TET).status_code == 200
    r = s.req("PUT", "/tags", json={"singular": []})
    assert r.status_code == 200 and r.json() == {"version": 2}


def test_if_match_on_change(daemon):
    s = Session(daemon)
    assert s.put_complex(TET).status_code == 200
    assert s.put_complex(TET, headers={"If-Match": '"7"'}).status_code == 412
    r = s.put_complex(TET, headers={"If-Match": '"1"'})
    assert r.status_code == 200 and r.json()["version"] == 2
    assert s.put_complex(TET, headers={"If-Match": "*"}).status_code == 200


# ---- levels -------------------------------------------------------------------------------------

def split_counts(ntet, noct, levels):
    """Tets and octahedra per level from the split table (001 Sec. 2: tet -> 4 tets + 1 oct,
    oct -> 8 tets + 6 octs)."""
    out = [(ntet, noct)]
    for _ in range(levels):
        t, o = out[-1]
        out.append((4 * t + 8 * o, t + 6 * o))
    return out


@pytest.mark.parametrize("mesh,opts", [(MIXED, {}), (CUBE, {}), (CUBE, {"solid_scheme": "averaged"})])
def test_level_json_matches_sdlevel(daemon, mesh, opts):
    s = Session(daemon)
    if opts:
        assert s.req("PUT", "/rules", json=opts).status_code == 200
    assert s.put_complex(complex_from_text(mesh)).status_code == 200
    flags = ["-s", "averaged"] if opts else []
    for level in (0, 1, 2):
        r = s.level(level, format="json")
        assert r.status_code == 200 and r.headers["Content-Type"].startswith("application/json")
        j = r.json()
        ref = sdlevel(mesh, level, *flags)
        assert j["level"] == level
        np.testing.assert_allclose(np.array(j["vertices"]), ref["verts"], rtol=0, atol=1e-12)
        for key in ("points", "edges", "triangles", "tetrahedra", "octahedra"):
            got = np.array(j["cells"][key], dtype=np.int64).reshape(ref[key].shape)
            assert np.array_equal(got, ref[key]), key
        assert len(j["rules"]) == len(ref["verts"])
        if level:
            for i, o in enumerate(ref["origins"]):
                if o[0] == "V":
                    assert j["origin"]["vertex_of"][i] == o[1]
                elif o[0] == "E":
                    assert sorted(j["origin"]["edge_of"][i]) == sorted(o[1:])
                elif o[0] == "C":
                    assert j["origin"]["cell_of"][i] == o[1]


def test_level_counts_follow_split_table(daemon):
    body = complex_from_text(CUBE)
    ntet = sum(1 for x in body["simplices"] if len(x) == 4)
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    table = split_counts(ntet, 0, 3)
    for level in range(4):
        st = s.req("GET", f"/levels/{level}/stats")
        assert st.status_code == 200, st.text
        c = st.json()["counts"]
        assert (c["tetrahedra"], c["octahedra"]) == table[level]
        assert st.json()["seconds"] >= 0 and st.json()["bytes"]["glb"] > 0
    # vertices: V_{l+1} = V_l + E_l + O_l (a point per vertex, edge and octahedron)
    for level in range(3):
        a = s.req("GET", f"/levels/{level}/stats").json()["counts"]
        b = s.req("GET", f"/levels/{level + 1}/stats").json()["counts"]
        assert b["vertices"] == a["vertices"] + a["edges"] + a["octahedra"]


def test_level_headers_etag_and_sizes(daemon):
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    types = {"glb": "model/gltf-binary", "gltf": "model/gltf+json",
             "vtu": "application/vnd.unstructured-grid+xml", "vtk": "application/octet-stream",
             "json": "application/json"}
    stats = s.req("GET", "/levels/2/stats").json()
    for fmt, ctype in types.items():
        r = s.level(2, format=fmt)
        assert r.status_code == 200
        assert r.headers["Content-Type"].startswith(ctype)
        assert r.headers["ETag"] == '"1"'
        if "Content-Length" in r.headers:
            assert int(r.headers["Content-Length"]) == len(r.content)
        if fmt in stats["bytes"]:
            assert stats["bytes"][fmt] == len(r.content)
        if fmt in ("vtu", "vtk"):
            assert r.headers["Content-Disposition"] == f'attachment; filename="level-2.{fmt}"'
    r = s.level(2)  # default format
    assert r.headers["Content-Type"] == "model/gltf-binary" and r.content[:4] == b"glTF"
    nm = s.req("GET", "/levels/2", headers={"If-None-Match": '"1"'})
    assert nm.status_code == 304 and nm.content == b""
    assert s.req("GET", "/levels/2", headers={"If-None-Match": '"0"'}).status_code == 200


def test_stats_bytes_are_the_download_sizes(daemon):
    """stats.bytes[fmt] is the length of GET /levels/L?format=fmt with default options (every
    attribute, all parts), with and without attributes, at one- and two-digit versions."""
    with_attrs = json.loads((REPO / "examples" / "mixed.json").read_text())
    vec = dict(TET, attributes={"t": [0.5, 1, 2, 3], "v": [[1, 2], [3, 4], [5, 6], [7, 8]]})
    cases = [complex_from_text(MIXED), with_attrs, complex_from_text(CUBE), vec]
    for body in cases:
        s = Session(daemon)
        for puts in (1, 10):  # versions 1 and 10: the version is written into the outputs
            while s.req("GET").json()["version"] < puts:
                assert s.put_complex(body).status_code == 200
            for level in (0, 1, 2):
                stats = s.req("GET", f"/levels/{level}/stats").json()
                assert {"glb", "gltf"} <= set(stats["bytes"])
                for fmt, n in stats["bytes"].items():
                    r = s.level(level, format=fmt)
                    assert r.status_code == 200, r.text
                    assert n == len(r.content), (fmt, level, puts, body.get("attributes"))


def test_format_table_is_what_everything_reads(daemon):
    """`subdivd --list-formats` (the table of api/formats.c) is what the daemon serves, what the
    OpenAPI document lists (the format enum and the level's content types), what the Python client
    knows, what an unknown format= names and what the offline mode takes as an extension."""
    out = subprocess.run([str(SUBDIVD), "--list-formats"], check=True, capture_output=True,
                         text=True).stdout
    table = [line.split(" ") for line in out.splitlines()]
    assert table and all(len(row) == 4 for row in table)
    names = [row[0] for row in table]
    doc = json.loads((REPO / "api" / "openapi.json").read_text(encoding="utf-8"))
    level = doc["paths"]["/v1/sessions/{id}/levels/{L}"]["get"]
    param = next(p for p in level["parameters"] if p["name"] == "format")
    assert param["schema"]["enum"] == names and param["schema"]["default"] == names[0]
    assert set(level["responses"]["200"]["content"]) == {row[1] for row in table}
    import sys
    sys.path.insert(0, str(REPO / "clients" / "python"))
    from subdiv import client
    assert list(client.FORMATS) == names
    s = Session(daemon)
    assert s.put_complex(TET).status_code == 200
    for name, mime, ext, disposition in table:
        r = s.level(1, format=name)
        assert r.status_code == 200 and r.headers["Content-Type"] == mime
        assert r.headers["Content-Disposition"] == f'{disposition}; filename="level-1{ext}"'
        assert ext == "." + name
    bad = s.level(1, format="obj").json()
    assert bad["detail"] == 'format "obj" is not one of ' + ", ".join(names)


def test_parts_and_attributes_in_json(daemon):
    body = complex_from_text(MIXED)
    body["attributes"] = {"t": [float(i) for i in range(8)]}
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    j = s.level(1, format="json", parts="curves,points").json()
    assert j["cells"]["triangles"] == [] and j["cells"]["tetrahedra"] == []
    assert len(j["cells"]["edges"]) == 4 and len(j["cells"]["points"]) == 1
    # an attribute is subdivided by the same matrices as the positions: a linear function of
    # the input stays that function wherever the rules are affine combinations
    full = s.level(1, format="json").json()
    assert len(full["attributes"]["t"]) == len(full["vertices"])
    none = s.level(1, format="json", attributes="").json()
    assert none.get("attributes", {}) == {}


def test_progress_is_reported():
    d = Daemon()
    try:
        mesh = make_mesh_file(pathlib.Path(d.proc.args[0]).parent, "cubes", 6)
        s = Session(d)
        assert s.put_complex(complex_from_text(mesh)).status_code == 200
        seen = []
        t = threading.Thread(target=lambda: seen.append(s.req("GET", "/levels/3/stats").status_code))
        t.start()
        samples = []
        deadline = time.time() + 60
        while t.is_alive() and time.time() < deadline:
            p = s.req("GET").json()["progress"]
            if p:
                samples.append(p)
            time.sleep(0.005)
        t.join()
        assert seen == [200]
        assert samples, "the computation was never seen"
        progress = samples[0]
        assert progress["state"] == "computing"
        assert 0 <= progress["level"] <= 3 and progress["seconds"] >= 0
        # levels are computed one at a time: the fraction of their bytes done, never backwards
        fractions = [p["fraction"] for p in samples if "fraction" in p]
        assert fractions and all(0 <= f < 1 for f in fractions), samples
        assert fractions == sorted(fractions)
    finally:
        assert d.stop() == 0


# ---- CORS, logs, shutdown ------------------------------------------------------------------------

def test_cors(daemon):
    s = Session(daemon)
    r = requests.options(s.base + "/complex", headers={
        "Origin": "http://example.test", "Access-Control-Request-Method": "PUT",
        "Access-Control-Request-Headers": "authorization, content-type, if-match"})
    assert r.status_code == 204
    assert r.headers["Access-Control-Allow-Origin"] == "*"
    assert "PUT" in r.headers["Access-Control-Allow-Methods"]
    allowed = r.headers["Access-Control-Allow-Headers"].lower()
    for h in ("authorization", "content-type", "if-match"):
        assert h in allowed
    g = s.req("GET", headers={"Origin": "http://example.test"})
    assert "ETag" in g.headers["Access-Control-Expose-Headers"]


def test_one_log_line_per_request(daemon):
    s = Session(daemon)
    n0 = len(daemon.log_lines)
    s.req("GET", "/complex")
    time.sleep(0.2)
    new = [l for l in daemon.log_lines[n0:] if s.id in l]
    assert len(new) == 1
    assert re.search(rf"info GET /v1/sessions/{s.id}/complex 409 \d+B [\d.]+ms "
                     r"route=/v1/sessions/\{id\}/complex type=/errors/no-complex$", new[0])
    assert s.token not in "\n".join(daemon.log_lines)


def test_sigint_clean_shutdown():
    d = Daemon()
    s = Session(d)
    assert s.put_complex(TET).status_code == 200
    d.proc.send_signal(signal.SIGINT)
    assert d.proc.wait(10) == 0
    d.stop()
    assert any("stopped" in l for l in d.log_lines)


# ---- offline mode ---------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", ["json", "glb", "gltf", "vtu", "vtk"])
def test_offline_refine_same_bytes(daemon, tmp_path, fmt):
    """`subdivd refine` and GET /levels give the same bytes (both at version 1)."""
    body = complex_from_text(MIXED)
    body["attributes"] = {"t": [float(i) for i in range(8)]}
    inp = tmp_path / "in.json"
    inp.write_text(json.dumps(body))
    out = tmp_path / f"out.{fmt}"
    cmap = {"colormap": "t:0:7"} if fmt in ("glb", "gltf") else {}   # COLOR_0 is glTF's
    r = subprocess.run([str(SUBDIVD), "refine", str(inp), "--level", "2", "--slice", "0,0,1,0.3",
                        *(a for k, v in cmap.items() for a in (f"--{k}", v)), "-o", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = Session(daemon)
    assert s.put_complex(body).status_code == 200
    http = s.level(2, format=fmt, slice="0,0,1,0.3", **cmap)
    assert http.status_code == 200
    assert out.read_bytes() == http.content
    if fmt in ("glb", "gltf"):
        r = subprocess.run(["node", str(REPO / "tests" / "tools" / "gltf_validate.js"), str(out)],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stdout


def test_offline_refine_rules(tmp_path):
    inp = tmp_path / "in.json"
    inp.write_text(json.dumps(complex_from_text(CUBE)))
    rules = tmp_path / "rules.json"
    rules.write_text(json.dumps({"solid_scheme": "averaged", "surface_weights": "loop"}))
    out = tmp_path / "out.json"
    r = subprocess.run([str(SUBDIVD), "refine", str(inp), "-l", "1", "--rules", str(rules),
                        "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ref = sdlevel(CUBE, 1, "-s", "averaged", "-w", "loop")
    got = np.array(json.loads(out.read_text())["vertices"])
    np.testing.assert_allclose(got, ref["verts"], rtol=0, atol=1e-12)


def test_offline_refine_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"vertices": [[0, 0, 0], [1, 0, 0]], "simplices": [[0, 5]]}))
    out = tmp_path / "o.glb"
    r = subprocess.run([str(SUBDIVD), "refine", str(bad), "--level", "1", "-o", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 1
    assert '"/simplices/0/1"' in r.stderr and "out of range" in r.stderr
    assert not out.exists() and not (tmp_path / "o.glb.part").exists()
    r = subprocess.run([str(SUBDIVD), "refine", str(bad), "--level", "1", "-o", str(tmp_path / "x.obj")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "format" in r.stderr


def test_reads_of_a_computing_session_do_not_wait(tmp_path):
    """GET /complex and the session state answer while the same session computes a level."""
    d = Daemon()
    try:
        s = Session(d)
        assert s.put_complex(complex_from_text(make_mesh_file(tmp_path, "cubes", 8))).status_code == 200
        t = threading.Thread(target=lambda: s.req("GET", "/levels/4/stats"))
        t.start()
        worst, n = 0.0, 0
        time.sleep(0.05)
        while t.is_alive():
            a = time.time()
            assert s.req("GET", "/complex").status_code == 200
            assert s.req("GET").status_code == 200
            worst = max(worst, time.time() - a)
            n += 1
        t.join()
        assert n >= 2
        assert worst < 0.5 * SLOW, f"a read waited {worst:.2f} s behind its own session's computation"
    finally:
        assert d.stop() == 0
