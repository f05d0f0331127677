"""The catalogue of malformed and hostile requests: each gets the right 4xx problem+json (with the
pointer of the offending field where there is one), the daemon stays up, and a bystander
session is byte-for-byte unaffected."""
import json
import socket

import pytest
import requests

from daemon import Daemon, Session

TET = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}
FIN = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]],
       "simplices": [[0, 1, 2, 3], [1, 2, 4]]}


def cx(**kw):
    b = json.loads(json.dumps(TET))
    b.update(kw)
    return b


# (id, method, path under the session ("" = the session, None = the daemon root path given in
#  body), body (dict -> JSON, bytes -> raw), headers, expected status, expected pointer or None)
J = {"Content-Type": "application/json"}
CASES = [
    # --- malformed JSON ---
    ("truncated", "PUT", "/complex", b'{"vertices": [[0,0,0]', J, 400, None),
    ("trailing-garbage", "PUT", "/complex", b'{"vertices": []} x', J, 400, None),
    ("nan-literal", "PUT", "/complex", b'{"vertices": [[NaN,0,0]], "simplices": [[0]]}', J, 400, None),
    ("infinity-literal", "PUT", "/complex", b'{"vertices": [[Infinity,0,0]], "simplices": [[0]]}', J, 400, None),
    ("neg-infinity", "PUT", "/complex", b'{"vertices": [[-Infinity,0,0]], "simplices": [[0]]}', J, 400, None),
    ("overflow-real", "PUT", "/complex", b'{"vertices": [[1e999,0,0]], "simplices": [[0]]}', J, 400, None),
    ("overflow-int", "PUT", "/complex", b'{"vertices": [[0,0,0]], "simplices": [[99999999999999999999999]]}', J, 400, None),
    ("duplicate-key", "PUT", "/complex", b'{"vertices": [[0,0,0]], "vertices": [[1,1,1]], "simplices": [[0]]}', J, 400, None),
    ("top-level-array", "PUT", "/complex", b'[1,2,3]', J, 400, ""),
    ("top-level-string", "PUT", "/complex", b'"hello"', J, 400, None),
    ("top-level-number", "PUT", "/complex", b'42', J, 400, None),
    ("deep-20", "PUT", "/complex", b'{"vertices":' + b"[" * 20 + b"]" * 20 + b"}", J, 400, None),
    ("deep-5000", "PUT", "/complex", b'{"a":' + b"[" * 5000 + b"]" * 5000 + b"}", J, 400, None),
    ("invalid-utf8", "PUT", "/complex", b'{"vertices": "\xff\xfe"}', J, 400, None),
    ("nul-in-string", "PUT", "/complex", b'{"vertices": "a\\u0000b"}', J, 400, None),
    ("empty-body", "PUT", "/complex", b'', J, 400, None),
    ("whitespace-body", "PUT", "/complex", b'   \n ', J, 400, None),
    # --- wrong types and shapes ---
    ("vertices-not-array", "PUT", "/complex", {"vertices": 3, "simplices": [[0]]}, None, 400, "/vertices"),
    ("vertex-2-coords", "PUT", "/complex", cx(vertices=[[0, 0, 0], [1, 0], [0, 1, 0], [0, 0, 1]]), None, 400, "/vertices/1"),
    ("vertex-4-coords", "PUT", "/complex", cx(vertices=[[0, 0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), None, 400, "/vertices/0"),
    ("coord-string", "PUT", "/complex", cx(vertices=[[0, 0, 0], [1, "0", 0], [0, 1, 0], [0, 0, 1]]), None, 400, "/vertices/1/1"),
    ("coord-bool", "PUT", "/complex", cx(vertices=[[0, 0, True], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), None, 400, "/vertices/0/2"),
    ("coord-null", "PUT", "/complex", cx(vertices=[[0, 0, 0], [1, 0, 0], [None, 1, 0], [0, 0, 1]]), None, 400, "/vertices/2/0"),
    ("index-float", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3.0]]), None, 400, "/simplices/0/3"),
    ("index-string", "PUT", "/complex", cx(simplices=[[0, "1", 2, 3]]), None, 400, "/simplices/0/1"),
    ("simplex-not-array", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3], 4]), None, 400, "/simplices/1"),
    ("simplices-missing", "PUT", "/complex", {"vertices": TET["vertices"]}, None, 400, "/simplices"),
    ("vertices-missing", "PUT", "/complex", {"simplices": [[0]]}, None, 400, "/vertices"),
    ("simplices-object", "PUT", "/complex", cx(simplices={"a": 1}), None, 400, "/simplices"),
    ("attributes-not-object", "PUT", "/complex", cx(attributes=[1, 2]), None, 400, "/attributes"),
    ("attribute-not-array", "PUT", "/complex", cx(attributes={"t": 5}), None, 400, "/attributes/t"),
    ("attribute-mixed", "PUT", "/complex", cx(attributes={"t": [1, [2], 3, 4]}), None, 400, "/attributes/t/1"),
    ("attribute-string", "PUT", "/complex", cx(attributes={"t": [1, 2, "x", 4]}), None, 400, "/attributes/t/2"),
    ("unknown-field", "PUT", "/complex", cx(colour="red"), None, 400, "/colour"),
    ("ttl-string", "POST", None, {"ttl_s": "10"}, None, 400, "/ttl_s"),
    ("ttl-zero", "POST", None, {"ttl_s": 0}, None, 422, "/ttl_s"),
    ("ttl-huge", "POST", None, {"ttl_s": 10 ** 12}, None, 422, "/ttl_s"),
    ("session-unknown-field", "POST", None, {"ttl": 5}, None, 400, "/ttl"),
    # --- semantic mesh errors ---
    ("index-out-of-range", "PUT", "/complex", cx(simplices=[[0, 1, 2, 17]]), None, 422, "/simplices/0/3"),
    ("index-negative", "PUT", "/complex", cx(simplices=[[0, 1, -2, 3]]), None, 422, "/simplices/0/2"),
    ("index-late", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3]] * 1203 + [[0, 1, 2, 4]]), None,
     422, "/simplices/1203/3"),
    ("simplex-size-late", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3]] * 120 + [[0, 1, 2, 3, 0]]),
     None, 422, "/simplices/120"),
    ("coord-late", "PUT", "/complex", cx(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]] * 26
                                          + [[0, 0, "z"]], simplices=[[0, 1, 2, 3]]), None, 400,
     "/vertices/104/2"),
    ("index-2-32", "PUT", "/complex", cx(simplices=[[0, 1, 2, 2 ** 32]]), None, 422, "/simplices/0/3"),
    ("repeated-vertex", "PUT", "/complex", cx(simplices=[[0, 1, 1, 3]]), None, 422, "/simplices/0/2"),
    ("duplicate-simplex", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3], [3, 2, 1, 0]]), None, 422, "/simplices/1"),
    ("five-vertices", "PUT", "/complex", cx(vertices=TET["vertices"] + [[1, 1, 1]], simplices=[[0, 1, 2, 3, 4]]), None, 422, "/simplices/0"),
    ("empty-simplex", "PUT", "/complex", cx(simplices=[[0, 1, 2, 3], []]), None, 422, "/simplices/1"),
    ("degenerate-edge", "PUT", "/complex", {"vertices": [[0, 0, 0], [0, 0, 0], [1, 0, 0]], "simplices": [[0, 1], [1, 2]]}, None, 422, "/simplices/0"),
    ("degenerate-triangle", "PUT", "/complex", {"vertices": [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "simplices": [[0, 1, 2]]}, None, 422, "/simplices/0"),
    ("degenerate-tet", "PUT", "/complex", {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], "simplices": [[0, 1, 2, 3]]}, None, 422, "/simplices/0"),
    ("huge-coordinate", "PUT", "/complex", cx(vertices=[[0, 0, 0], [1e300, 0, 0], [0, 1, 0], [0, 0, 1]]), None, 422, "/vertices/1/0"),
    ("no-vertices", "PUT", "/complex", {"vertices": [], "simplices": []}, None, 422, None),
    ("no-simplices", "PUT", "/complex", {"vertices": [[0, 0, 0]], "simplices": []}, None, 422, None),
    ("attribute-wrong-length", "PUT", "/complex", cx(attributes={"t": [1, 2, 3]}), None, 422, "/attributes/t"),
    ("attribute-bad-name", "PUT", "/complex", cx(attributes={"a b": [1, 2, 3, 4]}), None, 422, "/attributes/a b"),
    ("attribute-17-components", "PUT", "/complex", cx(attributes={"v": [[0] * 17] * 4}), None, 422, "/attributes/v/0"),
    ("too-many-attributes", "PUT", "/complex", cx(attributes={f"a{i}": [0, 0, 0, 0] for i in range(17)}), None, 422, "/attributes"),
    # --- rules and tags ---
    ("scheme-unknown", "PUT", "/rules", {"solid_scheme": "cubic"}, None, 422, "/solid_scheme"),
    ("weights-number", "PUT", "/rules", {"surface_weights": 3}, None, 400, "/surface_weights"),
    ("nm-default-N1", "PUT", "/rules", {"nonmanifold_default": "N1"}, None, 422, "/nonmanifold_default"),
    ("nm-default-unknown", "PUT", "/rules", {"nonmanifold_default": "G3"}, None, 422, "/nonmanifold_default"),
    ("rules-unknown-field", "PUT", "/rules", {"smoothness": 1}, None, 400, "/smoothness"),
    ("override-unknown-field", "PUT", "/rules", {"overrides": [{"simplex": [1], "rule": "G1", "x": 1}]}, None, 400, "/overrides/0/x"),
    ("overrides-not-array", "PUT", "/rules", {"overrides": {}}, None, 400, "/overrides"),
    ("override-manifold-vertex", "PUT", "/rules", {"overrides": [{"simplex": [1], "rule": "G1"}]}, None, 422, "/overrides/0/simplex"),
    ("fill-one-triangle", "PUT", "/complex", cx(fill=[{"surface": [[0, 1, 2]]}]), None, 422, "/fill/0/surface"),
    ("fill-repeated-triangle", "PUT", "/complex", cx(fill=[{"surface": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [0, 1, 2]]}]), None, 422, "/fill/0/surface/3"),
    ("tags-arity", "PUT", "/tags", {"singular": [[0, 1, 2, 3]]}, None, 422, "/singular/0"),
    ("tags-range", "PUT", "/tags", {"singular": [[0, 9]]}, None, 422, "/singular/0/1"),
    ("tags-repeated", "PUT", "/tags", {"singular": [[1, 1]]}, None, 422, "/singular/0/1"),
    ("tags-type", "PUT", "/tags", {"singular": [[0, "1"]]}, None, 400, "/singular/0/1"),
    ("tags-missing", "PUT", "/tags", {}, None, 400, "/singular"),
    # --- levels ---
    ("level-letters", "GET", "/levels/abc", None, None, 400, "level"),
    ("level-negative", "GET", "/levels/-1", None, None, 400, "level"),
    ("level-13", "GET", "/levels/13", None, None, 422, "level"),
    ("level-huge", "GET", "/levels/99999999999999999999", None, None, 422, None),
    # a segment too long for the router to hold is still a level or a name, refused as such
    ("level-64-digits", "GET", "/levels/" + "9" * 64, None, None, 400, "level"),
    ("level-long-stats", "GET", "/levels/" + "x" * 70 + "/stats", None, None, 400, "level"),
    ("level-long-delta", "GET", "/levels/" + "1" * 80 + "/delta?since=1", None, None, 400, "level"),
    ("matrix-long", "GET", "/matrices/" + "2" * 65, None, None, 400, "level"),
    ("embedded-long-name", "PUT", "/embedded/" + "m" * 64, {"vertices": [[0.1, 0.1, 0.1]]}, None, 400, "name"),
    ("embedded-long-get", "GET", "/embedded/" + "m" * 100, None, None, 400, "name"),
    ("embedded-long-delta", "GET", "/embedded/" + "m" * 100 + "/delta?since=1", None, None, 400, "name"),
    ("embedded-long-delete", "DELETE", "/embedded/" + "m" * 100, None, None, 400, "name"),
    ("embedded-bad-name-get", "GET", "/embedded/a.b", None, None, 400, "name"),
    ("level-unknown-param", "GET", "/levels/1?colour=red", None, None, 400, "colour"),
    ("level-bad-format", "GET", "/levels/1?format=obj", None, None, 422, "format"),
    ("level-bad-parts", "GET", "/levels/1?parts=volumes", None, None, 422, "parts"),
    ("level-bad-slice", "GET", "/levels/1?slice=1,2,3", None, None, 422, "slice"),
    ("level-zero-normal", "GET", "/levels/1?slice=0,0,0,1", None, None, 422, "slice"),
    ("level-nan-slice", "GET", "/levels/1?slice=nan,0,1,0", None, None, 422, "slice"),
    ("level-bad-colormap", "GET", "/levels/1?colormap=t:5:1", None, None, 422, "colormap"),
    ("level-unknown-attr", "GET", "/levels/1?attributes=nope", None, None, 422, "attributes"),
    ("level-bad-octahedra", "GET", "/levels/1?octahedra=cubes", None, None, 422, "octahedra"),
    ("stats-param", "GET", "/levels/1/stats?x=1", None, None, 400, "x"),
    # --- transport ---
    ("wrong-content-type", "PUT", "/complex", json.dumps(TET).encode(), {"Content-Type": "text/plain"}, 415, None),
    ("body-on-get", "GET", "/complex", b'{"a":1}', J, 400, None),
    ("wrong-method", "POST", "/complex", TET, None, 405, None),
    ("patch-session-no-ttl", "PATCH", "", {}, None, 400, "/ttl_s"),
    # an edit of nothing names the two members it takes (it had no pointer at all)
    ("patch-edit-empty", "PATCH", "/control-points", {}, {"If-Match": '"1"'}, 400, "/moves"),
    ("put-session", "PUT", "", {}, None, 405, None),
    ("unknown-subpath", "GET", "/nothing", None, None, 404, None),
    ("stale-if-match", "PUT", "/complex", TET, {"If-Match": '"999"'}, 412, None),
]


@pytest.fixture(scope="module")
def daemon():
    d = Daemon("--max-sessions", "1000")
    yield d
    assert d.stop() == 0


@pytest.fixture(scope="module")
def bystander(daemon):
    s = Session(daemon)
    assert s.put_complex(FIN).status_code == 200
    snap = (s.req("GET").json()["version"], s.req("GET", "/complex").content,
            s.level(2).content, s.level(2, format="vtu").content)
    return s, snap


def check_problem(r, status, pointer):
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"] == "application/problem+json"
    p = r.json()
    assert p["status"] == status and p["type"].startswith("/errors/") and p["title"] and p["detail"]
    if pointer is not None:
        assert p["errors"][0]["pointer"] == pointer, p


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_catalogue(daemon, bystander, case):
    name, method, path, body, headers, status, pointer = case
    s = Session(daemon)
    if path is not None and path != "/complex" and method != "POST":
        assert s.put_complex(TET).status_code == 200   # level and rule requests need a complex
    kw = {"headers": dict(headers or {})}
    if isinstance(body, (bytes, str)):
        kw["data"] = body
    elif body is not None:
        kw["json"] = body
    if path is None:
        r = requests.request(method, daemon.url + "/v1/sessions", timeout=30, **kw)
    else:
        r = s.req(method, path, **kw)
    check_problem(r, status, pointer)
    if status == 405:
        assert r.headers["Allow"]
    assert daemon.alive()
    assert requests.get(daemon.url + "/healthz").status_code == 200
    # the refused change left the session as it was
    if path is not None and method == "PUT":
        v = s.req("GET").json()["version"]
        assert v == (0 if path == "/complex" and name != "stale-if-match" else 1) or name == "stale-if-match"


def test_bystander_unchanged(daemon, bystander):
    s, snap = bystander
    now = (s.req("GET").json()["version"], s.req("GET", "/complex").content,
           s.level(2).content, s.level(2, format="vtu").content)
    assert now == snap


def test_slice_normal_of_any_magnitude(daemon):
    """slice=nx,ny,nz,d with n far from unit (docs/OUTPUTS.md: n need not be unit) is the plane
    of the unit n: n = 2^-700 (0, not a zero normal, and whose square underflows) and 2^600
    (whose square overflows) answer what n = 1 does."""
    s = Session(daemon)
    assert s.put_complex(TET).status_code == 200
    want = s.level(1, format="json", slice="1,0,0,0.3")
    assert want.status_code == 200 and want.json()["slice"]["triangles"]
    for k in (2.0 ** -700, 2.0 ** 600):
        r = s.level(1, format="json", slice=f"{k!r},0,0,{0.3 * k!r}")
        assert r.status_code == 200, r.text
        assert r.content == want.content


# a bad level option and the option its problem names (pointer, and what detail starts with)
LEVEL_OPTION_CASES = [
    ({"parts": "volumes"}, "parts"),
    ({"parts": ""}, "parts"),
    ({"parts": "points,points"}, "parts"),
    ({"slice": "1,2,3"}, "slice"),
    ({"slice": "0,0,0,1"}, "slice"),
    ({"slice": "nan,0,1,0"}, "slice"),
    ({"colormap": "t"}, "colormap"),
    ({"colormap": "t:5:1"}, "colormap"),
    ({"colormap": "nope:0:1"}, "colormap"),
    ({"format": "vtu", "colormap": "t:0:1"}, "colormap"),
    ({"format": "json", "colormap": "t:0:1"}, "colormap"),
    ({"attributes": "nope"}, "attributes"),
    ({"attributes": "t,t"}, "attributes"),
    ({"format": "vtu", "octahedra": "cubes"}, "octahedra"),
    ({"format": "glb", "octahedra": "tets"}, "octahedra"),
    ({"format": "vtu", "names": "yes"}, "names"),
    ({"format": "json", "names": "false"}, "names"),
    ({"format": "vtu", "compress": "gzip"}, "compress"),
    ({"format": "json", "compress": "none"}, "compress"),
    ({"limit": "yes"}, "limit"),
    # a list ending in a comma ends in an empty item, refused as one at the start is
    ({"parts": "points,"}, "parts"),
    ({"attributes": "t,"}, "attributes"),
    ({"slice": "1,0,0,0.3,"}, "slice"),
    # numbers in decimal only: strtod would also take blanks before them and hexadecimal
    ({"slice": " 1,0,0,0.3"}, "slice"),
    ({"slice": "1,0,0,0x1p-2"}, "slice"),
    ({"colormap": "t: 0:1"}, "colormap"),
    ({"colormap": "t:0:0x10"}, "colormap"),
    # an item longer than the parser holds is refused, not cut: cut after 63 characters this d
    # (0.5e5) would be read as 0.5, another plane
    ({"slice": "1,0,0,0.5" + "0" * 62 + "e5"}, "slice"),
    ({"parts": "s" * 70}, "parts"),
]


@pytest.mark.parametrize("params,option", LEVEL_OPTION_CASES,
                         ids=["-".join(f"{k}={v}" for k, v in c[0].items()) for c in LEVEL_OPTION_CASES])
def test_level_option_problem_names_the_option(daemon, params, option):
    """docs/OUTPUTS.md: a bad level option is refused with a message that starts with the
    option's name and a colon, with the parameter as errors[0].pointer."""
    s = Session(daemon)
    assert s.put_complex(cx(attributes={"t": [0, 1, 2, 3]})).status_code == 200
    r = s.level(1, **params)
    check_problem(r, 422, option)
    assert r.json()["detail"].startswith(option + ":"), r.json()


def test_refused_change_keeps_state(daemon):
    s = Session(daemon)
    assert s.put_complex(FIN).status_code == 200
    before = (s.req("GET", "/complex").content, s.level(1, format="json").content)
    for bad in (cx(simplices=[[0, 1, 2, 9]]), {"vertices": 1}):
        assert s.put_complex(bad).status_code in (400, 422)
    assert s.req("PUT", "/rules", json={"solid_scheme": "x"}).status_code == 422
    assert (s.req("GET", "/complex").content, s.level(1, format="json").content) == before
    assert s.req("GET").json()["version"] == 1


def test_needs_a_complex_first(daemon):
    s = Session(daemon)
    check_problem(s.req("PUT", "/tags", json={"singular": [[0]]}), 409, "/singular")
    check_problem(s.req("PUT", "/rules", json={"overrides": [{"simplex": [0], "rule": "G1"}]}), 409, "/overrides")
    check_problem(s.req("GET", "/complex"), 409, None)
    check_problem(s.level(1), 409, None)
    check_problem(s.req("GET", "/levels/1/stats"), 409, None)
    assert s.req("PUT", "/rules", json={"solid_scheme": "averaged"}).status_code == 200


def test_auth_errors(daemon):
    s, other = Session(daemon), Session(daemon)
    url = s.base + "/complex"
    for headers in ({}, {"Authorization": "Bearer nope"}, {"Authorization": s.token},
                    {"Authorization": f"Bearer {s.token}x"}, {"Authorization": f"Basic {s.token}"},
                    {"Authorization": f"Bearer {other.token}"}):
        r = requests.get(url, headers=headers)
        check_problem(r, 401, None)
        assert r.headers["WWW-Authenticate"].startswith("Bearer")
    # the scheme name is case-insensitive (RFC 9110 11.1)
    assert requests.get(s.base, headers={"Authorization": f"bearer {s.token}"}).status_code == 200
    check_problem(requests.get(daemon.url + "/v1/sessions/" + "0" * 32, headers=s.auth), 404, None)
    check_problem(requests.get(daemon.url + "/v1/sessions/xyz", headers=s.auth), 404, None)
    assert s.delete().status_code == 204
    check_problem(s.req("GET"), 404, None)


@pytest.mark.parametrize("vertices,why", [
    # an edge of 1 beside a point 4e12 away: short against the box (DECISIONS 7), not flat
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [4e12, 0, 0]], "an edge of zero or near-zero length"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e-13], [2, 2, 2]], "zero or near-zero volume"),
])
def test_a_degenerate_simplex_is_named_for_its_test(daemon, vertices, why):
    """The 422 says which test refused the simplex: an edge too short against the bounding box's
    diagonal, or a volume too small against its longest edge (it said "near-zero volume" for
    both)."""
    s = Session(daemon)
    r = s.put_complex({"vertices": vertices, "simplices": [[0, 1, 2, 3], [4]]})
    check_problem(r, 422, "/simplices/0")
    assert why in r.json()["detail"], r.json()


def test_paths_and_methods(daemon):
    for path in ("/nowhere", "/v1", "/v1/sessions/", "/../../etc/passwd", "/v1/" + "a" * 5000):
        r = requests.get(daemon.url + path)
        assert 400 <= r.status_code < 500
    r = requests.delete(daemon.url + "/v1/sessions")
    check_problem(r, 405, None)
    assert "POST" in r.headers["Allow"]
    check_problem(requests.put(daemon.url + "/healthz"), 405, None)
    check_problem(requests.post(daemon.url + "/", data=b"x"), 405, None)
    # a 405's Allow is the resource's methods, OPTIONS included (RFC 9110 15.5.6: every route
    # answers OPTIONS), the same list its preflight gives
    s = Session(daemon)
    for path, method in (("/v1/sessions", "DELETE"), ("/healthz", "PUT"), ("/", "POST"),
                         (s.base[len(daemon.url):] + "/complex", "POST")):
        refused = requests.request(method, daemon.url + path, headers=s.auth, data=b"x")
        options = requests.options(daemon.url + path)
        assert refused.status_code == 405 and options.status_code == 204, path
        assert refused.headers["Allow"] == options.headers["Allow"], (path, refused.headers)
        assert "OPTIONS" in refused.headers["Allow"].split(", ")
    # the detail names the method sent, an unknown one too (its token characters, cut at 20)
    for method, said in (("FOO", "FOO"), ("TRACE", "TRACE"), ("X" * 30, "X" * 20 + "...")):
        r = requests.request(method, daemon.url + "/v1/sessions")
        check_problem(r, 405, None)
        assert r.json()["detail"].startswith(said + " is not allowed on /v1/sessions"), r.text


def raw(daemon, request_bytes):
    host, port = daemon.url.split("//")[1].split(":")
    with socket.create_connection((host, int(port)), timeout=10) as c:
        c.sendall(request_bytes)
        data = b""
        while True:
            chunk = c.recv(65536)
            if not chunk:
                break
            data += chunk
            if b"\r\n\r\n" in data and len(data) > 2000:
                break
    return int(data.split(b" ", 2)[1])


def test_limits():
    d = Daemon("--max-cells", "1000", "--max-vertices", "50", "--max-body-bytes", "20000",
               "--max-sessions", "3", "--max-simplices", "100")
    try:
        s = Session(d)
        assert s.put_complex(TET).status_code == 200
        r = s.level(5)
        check_problem(r, 413, None)
        p = r.json()
        assert p["limit_name"] == "max_cells" and p["limit"] == 1000 and p["requested"] > 1000
        assert s.level(3).status_code == 200                  # 4^3 + ... = 704 cells: allowed
        big = {"vertices": [[i, i * i % 7, i % 3] for i in range(51)], "simplices": [[0]]}
        r = s.put_complex(big)
        check_problem(r, 413, None)
        assert r.json()["limit_name"] == "max_vertices" and r.json()["requested"] == 51
        many = {"vertices": [[i, 0, 0] for i in range(50)], "simplices": [[i] for i in range(50)] * 3}
        check_problem(s.put_complex(many), 413, None)
        r = s.req("PUT", "/complex", data=b" " * 30000, headers={"Content-Type": "application/json"})
        check_problem(r, 413, None)
        assert r.json()["limit_name"] == "max_body_bytes"
        # chunked upload over the limit (no Content-Length): refused after reading, not crashed
        host, port = d.url.split("//")[1].split(":")
        body = b"[" * 25000
        req = (f"PUT /v1/sessions/{s.id}/complex HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {s.token}\r\n"
               f"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
               f"{len(body):x}\r\n").encode() + body + b"\r\n0\r\n\r\n"
        assert raw(d, req) == 413
        # too many sessions (each resident one holds a complex: an empty one would make room)
        for _ in range(2):
            assert Session(d).put_complex(TET).status_code == 200
        r = requests.post(d.url + "/v1/sessions")
        check_problem(r, 429, None)
        assert r.headers["Retry-After"]
        assert requests.get(d.url + "/healthz").status_code == 200
        assert s.req("GET").json()["version"] == 1
    finally:
        assert d.stop() == 0


def test_a_magnitude_refusal_gives_the_value_as_sent(daemon):
    """A number past its bound is named with the digits that tell it from the bound: 1.0000001e15
    against 1e15 (it read "1e+15 exceeds the allowed magnitude 1e+15")."""
    s = Session(daemon)
    assert s.put_complex(TET).status_code == 200
    r = s.req("PATCH", "/control-points", headers={"If-Match": '"1"'},
              json={"moves": [{"index": 1, "position": [1.0000001e15, 0, 0]}]})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/moves/0/position/0", r.text
    assert r.json()["detail"] == "1.0000001e+15 exceeds the allowed magnitude 1e+15", r.text
    r = s.put_complex(cx(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, -1.0000001e15]]))
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/vertices/3/2", r.text
    assert "= -1.0000001e+15 exceeds the allowed magnitude 1e+15" in r.json()["detail"], r.text
    r = s.req("PATCH", "/control-points", headers={"If-Match": '"1"'},
              json={"moves": [{"index": 1, "position": [0, 1e300, 0]}]})
    assert r.json()["detail"] == "1e+300 exceeds the allowed magnitude 1e+15", r.text
