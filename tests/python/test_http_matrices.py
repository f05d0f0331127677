"""GET /matrices/{L}: the downloaded matrices reproduce the levels (P @ p^from = p^L to 1e-12), in
Matrix Market (read with scipy, an independent reader) and JSON CSR alike."""
import io
import json

import numpy as np
import pytest
import scipy.io
import scipy.sparse

from conftest import REPO
from daemon import Daemon, Session, complex_from_text

MIXED = REPO / "examples" / "mixed.txt"
CUBE = REPO / "tests" / "cases" / "tetgen_cube" / "mesh.txt"


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    assert d.stop() == 0


@pytest.mark.parametrize("mesh", [MIXED, CUBE])
def test_matrices_reproduce_levels(daemon, mesh):
    s = Session(daemon)
    body = complex_from_text(mesh)
    body["attributes"] = {"t": [float(i % 5) for i in range(len(body["vertices"]))]}
    assert s.put_complex(body).status_code == 200
    levels = [s.level(l, format="json").json() for l in range(3)]
    for frm, to in ((0, 1), (1, 2), (0, 2)):
        r = s.req("GET", f"/matrices/{to}", params={"from": frm})
        assert r.status_code == 200 and r.headers["Content-Type"].startswith("text/plain")
        P = scipy.io.mmread(io.BytesIO(r.content)).tocsr()
        src, dst = np.array(levels[frm]["vertices"]), np.array(levels[to]["vertices"])
        assert P.shape == (len(dst), len(src))
        np.testing.assert_allclose(P @ src, dst, rtol=0, atol=1e-12)
        np.testing.assert_allclose(P @ np.array(levels[frm]["attributes"]["t"]),
                                   levels[to]["attributes"]["t"], atol=1e-12)
        np.testing.assert_allclose(np.asarray(P.sum(axis=1)).ravel(), 1, atol=1e-12)
        j = s.req("GET", f"/matrices/{to}", params={"from": frm, "format": "json"}).json()
        Q = scipy.sparse.csr_matrix((j["val"], j["col"], j["rowptr"]), shape=(j["rows"], j["cols"]))
        assert j["nnz"] == Q.nnz == P.nnz and (j["from"], j["to"]) == (frm, to)
        assert abs(P - Q).max() == 0


def test_default_from_is_zero(daemon):
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    a = s.req("GET", "/matrices/2").content
    b = s.req("GET", "/matrices/2", params={"from": 0}).content
    assert a == b and a.startswith(b"%%MatrixMarket matrix coordinate real general")


@pytest.mark.parametrize("path,params,status", [
    ("/matrices/0", {}, 422), ("/matrices/2", {"from": 2}, 422), ("/matrices/2", {"from": "x"}, 400),
    ("/matrices/2", {"format": "csv"}, 422), ("/matrices/2", {"to": 1}, 400), ("/matrices/13", {}, 422)])
def test_matrix_errors(daemon, path, params, status):
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    r = s.req("GET", path, params=params)
    assert r.status_code == status, r.text
    assert r.headers["Content-Type"] == "application/problem+json"


@pytest.mark.parametrize("frm,name", [(None, "S_0_2"), ("1", "S_1_2"), ("01", "S_1_2"),
                                      ("0" * 120 + "1", "S_1_2")])
def test_attachment_names_the_parsed_levels(daemon, frm, name):
    """The file name carries the from-level as a number, not the query text: a long run of
    leading zeros used to overflow the header buffer and cut the quoted file name short."""
    s = Session(daemon)
    assert s.put_complex(complex_from_text(MIXED)).status_code == 200
    for fmt in ("mtx", "json"):
        params = {"format": fmt} if frm is None else {"from": frm, "format": fmt}
        r = s.req("GET", "/matrices/2", params=params)
        assert r.status_code == 200, r.text
        assert r.headers["Content-Disposition"] == f'attachment; filename="{name}.{fmt}"'
