"""Several daemons on one redis store behind HAProxy (deploy/haproxy.cfg, docs/DEPLOY.md).

- The routing of deploy/haproxy.cfg itself (needs only haproxy): every path of one session goes
  to one daemon, requests that name no session go round robin.
- Failover: a session edited 20 times through HAProxy; the daemon that served it is killed
  (SIGKILL); the next requests through HAProxy reach the other daemon, which loads the session
  from redis: the last acknowledged positions and version, and level 2 exactly as before.
- SIGTERM while a download is in flight: the download finishes, the session moves on.
- Two daemons, same session, the same If-Match at the same moment: exactly one 200, one 412;
  changes that name no version at the same moment: both made, one after the other.

The store tests need `subdivd --store` (the persistence integration); they skip while the daemon
does not offer it. HAProxy's configuration is deploy/haproxy.cfg with only its `bind` line and
its `server` addresses rewritten (and, for daemons run with fewer connections, its `maxconn` and
`timeout queue`), so the test checks the file that is shipped.
"""
import contextlib
import http.client
import pathlib
import re
import shutil
import subprocess
import threading
import time

import pytest
import requests

from conftest import REPO
from daemon import SUBDIVD, Daemon
from redisd import REDIS_SERVER, RedisServer, free_port

HAPROXY = shutil.which("haproxy")
CFG = REPO / "deploy" / "haproxy.cfg"

# two tetrahedra sharing the face (1, 2, 3)
TWO_TETS = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
            "simplices": [[0, 1, 2, 3], [1, 2, 3, 4]]}


def _daemon_has_store():
    try:
        r = subprocess.run([str(SUBDIVD), "--help"], capture_output=True, text=True, timeout=10)
    except OSError:
        return False
    return "--store" in r.stdout + r.stderr


needs_haproxy = pytest.mark.skipif(HAPROXY is None, reason="haproxy is not installed")
needs_store = pytest.mark.skipif(
    REDIS_SERVER is None or not _daemon_has_store(),
    reason="redis-server is not installed, or build/subdivd --help does not mention --store "
           "(the persistence integration has not landed)")


def haproxy_config(front_port, servers, maxconn=None, queue=None):
    """deploy/haproxy.cfg for this machine: the frontend on front_port, server n<k> at
    servers[k-1] ("host:port") in every backend; with maxconn=(sessions, any) the two backends'
    maxconn (for daemons run with fewer connections than the shipped 256) and with queue its
    `timeout queue`."""
    text = CFG.read_text()
    if maxconn:
        text, n = re.subn(r"(?m)^(\s*default-server\b.*\bmaxconn )\d+", lambda m: m.group(1) + "@",
                          text)
        assert n == 2, "deploy/haproxy.cfg: a maxconn in each backend's default-server expected"
        text = text.replace("@", str(maxconn[0]), 1).replace("@", str(maxconn[1]), 1)
    if queue:
        text, n = re.subn(r"(?m)^(\s*timeout queue )\S+", rf"\g<1>{queue}", text)
        assert n == 1
    text, n = re.subn(r"(?m)^(\s*bind\s+)\S+", rf"\g<1>127.0.0.1:{front_port}", text)
    assert n == 1, "deploy/haproxy.cfg: one bind line expected"
    names = set()

    def server(m):
        names.add(m.group(2))
        k = int(m.group(2)[1:])
        return m.group(1) + servers[k - 1]
    text = re.sub(r"(?m)^(\s*server\s+(n\d+)\s+)\S+", server, text)
    assert names == {f"n{k + 1}" for k in range(len(servers))}, names
    return text


class HAProxy:
    """haproxy in the foreground (-db) with the generated configuration; its log in `log`."""

    def __init__(self, directory, servers, **config):
        self.port = free_port()
        self.cfg = pathlib.Path(directory) / "haproxy.cfg"
        self.cfg.write_text(haproxy_config(self.port, servers, **config))
        chk = subprocess.run([HAPROXY, "-c", "-f", str(self.cfg)], capture_output=True, text=True)
        assert chk.returncode == 0, chk.stdout + chk.stderr
        self.logf = pathlib.Path(directory) / "haproxy.log"
        self.proc = subprocess.Popen([HAPROXY, "-db", "-f", str(self.cfg)],
                                     stdout=open(self.logf, "w"), stderr=subprocess.STDOUT)
        self.url = f"http://127.0.0.1:{self.port}"
        deadline = time.time() + 10
        while time.time() < deadline:
            try:
                requests.get(self.url + "/healthz", timeout=1)
                return
            except requests.ConnectionError:
                assert self.proc.poll() is None, self.log()
                time.sleep(0.05)
        raise RuntimeError("haproxy did not start:\n" + self.log())

    def log(self):
        return self.logf.read_text() if self.logf.exists() else ""

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def _addr(d):
    return d.url.split("//", 1)[1]


@contextlib.contextmanager
def haproxy_over_two(tmp_path):
    """Two daemons (memory store) behind HAProxy: the HAProxy; all stopped after."""
    daemons, hap = [Daemon() for _ in range(2)], None
    try:
        hap = HAProxy(tmp_path, [_addr(d) for d in daemons])
        yield hap
    finally:
        if hap:
            hap.stop()
        for d in daemons:
            d.stop()


@pytest.fixture
def cluster(tmp_path):
    """redis, two daemons on it, HAProxy in front: (haproxy, [daemon n1, daemon n2], redis)."""
    redis = RedisServer(tmp_path).start()
    daemons, hap = [], None
    try:
        daemons = [Daemon("--store", redis.url) for _ in range(2)]
        hap = HAProxy(tmp_path, [_addr(d) for d in daemons])
        yield hap, daemons, redis
    finally:
        if hap:
            hap.stop()
        for d in daemons:
            d.stop()
        redis.stop()


def test_shipped_config_is_valid():
    if HAPROXY is None:
        pytest.skip("haproxy is not installed")
    r = subprocess.run([HAPROXY, "-c", "-f", str(CFG)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


@needs_haproxy
def test_session_paths_hash_on_the_id(tmp_path):
    daemons = [Daemon() for _ in range(2)]
    hap = None
    try:
        hap = HAProxy(tmp_path, [_addr(d) for d in daemons])
        http = requests.Session()
        seen = set()
        for k in range(24):
            sid = f"{k:02d}" + "ab" * 15
            nodes = set()
            for path in ("", "/", "/complex", "/levels/2?format=json", "/levels/3/delta?since=1",
                         "/events", "/control-points"):
                method = "PATCH" if path == "/control-points" else "GET"
                r = http.request(method, f"{hap.url}/v1/sessions/{sid}{path}",
                                 headers={"Authorization": "Bearer x"}, timeout=10)
                assert r.status_code in (401, 404), (path, r.status_code, r.text)
                nodes.add(r.headers.get("X-Subdivd-Node"))
            assert len(nodes) == 1 and None not in nodes, (sid, nodes)
            seen |= nodes
        assert seen == {"n1", "n2"}, f"24 ids all hashed to {seen}"
        # no session in the path: round robin
        created = {http.post(hap.url + "/v1/sessions", json={}, timeout=10).headers.get("X-Subdivd-Node")
                   for _ in range(4)}
        assert created == {"n1", "n2"}, created
        # HAProxy limits new sessions per client address (the daemons see only its address)
        out = [http.post(hap.url + "/v1/sessions", json={}, timeout=10) for _ in range(28)]
        codes = [r.status_code for r in out]
        assert codes[:26] == [201] * 26 and codes[-1] == 429, codes
        # in the daemons' form (docs/SERVICE.md "Errors"): a problem with Retry-After
        assert_retry_problem(out[-1], 429, "session-rate")
    finally:
        if hap:
            hap.stop()
        for d in daemons:
            d.stop()


@needs_haproxy
def test_haproxy_log_has_no_query(tmp_path):
    """HAProxy's access log, like the daemons' own (docs/SERVICE.md "Starting"), writes the path
    of a request, never its query: GET /events takes the bearer token as ?access_token= (an
    EventSource cannot send headers), so a log of the request line would hold it."""
    with haproxy_over_two(tmp_path) as hap:
        sid = "cd" * 16
        secret = "Zq9xSecretTokenInTheQuery0123456789abcdefg"
        for path in (f"/v1/sessions/{sid}/events?access_token={secret}",
                     f"/v1/sessions/{sid}/levels/2?format=vtu&note={secret}",
                     f"/healthz?{secret}"):
            r = requests.get(hap.url + path, timeout=10)
            assert r.status_code in (200, 400, 401, 404), (path, r.status_code, r.text)
        deadline = time.time() + 10
        while time.time() < deadline and hap.log().count(f"/v1/sessions/{sid}/") < 2:
            time.sleep(0.1)
        log = hap.log()
        assert f'"GET /v1/sessions/{sid}/events HTTP/1.1"' in log, log
        assert f'"GET /v1/sessions/{sid}/levels/2 HTTP/1.1"' in log, log
        assert secret not in log, log


@needs_haproxy
def test_haproxy_session_rate_counts_encoded_paths(tmp_path):
    """The daemons read the path percent-decoded, so POST /v1/%73essions creates a session as
    POST /v1/sessions does: HAProxy's limit of 30 new sessions a minute per client address
    (the daemons run with theirs lifted, docs/DEPLOY.md) counts both spellings alike."""
    with haproxy_over_two(tmp_path) as hap:
        codes = []
        for path in ["/v1/%73essions", "/v1/s%65ssions", "/v1/sessions"] * 11:
            c = http.client.HTTPConnection("127.0.0.1", hap.port, timeout=10)
            c.request("POST", path, "{}", {"Content-Type": "application/json"})  # sent as is
            r = c.getresponse()
            r.read()
            codes.append(r.status)
            c.close()
        assert codes[:30] == [201] * 30 and codes[30:] == [429] * 3, codes


def assert_retry_problem(r, status, slug):
    """An answer of HAProxy's own in the daemons' form (docs/SERVICE.md "Errors"): a
    problem+json of that status and type, with Retry-After."""
    assert r.headers["Content-Type"] == "application/problem+json", r.headers
    assert r.json()["status"] == status and r.json()["type"] == f"/errors/{slug}", r.text
    assert int(r.headers["Retry-After"]) > 0


@needs_haproxy
def test_no_daemon_up_is_a_problem_with_retry_after(tmp_path):
    """With no daemon up (all stopped, or all not ready: redis down), HAProxy answers itself:
    503 in the daemons' form, a problem+json with Retry-After, which clients retry."""
    daemons = [Daemon() for _ in range(2)]
    hap = None
    try:
        hap = HAProxy(tmp_path, [_addr(d) for d in daemons])
        for d in daemons:
            assert d.stop() == 0
        time.sleep(2.5)   # fall 2, inter 1s: both marked down
        for method, path in (("POST", "/v1/sessions"), ("GET", "/v1/sessions/" + "ab" * 16),
                             ("GET", "/healthz")):
            r = requests.request(method, hap.url + path, json={} if method == "POST" else None,
                                 timeout=10)
            assert r.status_code == 503, (path, r.status_code, r.text)
            assert_retry_problem(r, 503, "not-ready")
    finally:
        if hap:
            hap.stop()
        for d in daemons:
            d.stop()


def _patch(http, url, token, version, moves):
    return http.patch(url + "/control-points", json={"moves": moves}, timeout=60,
                      headers={"Authorization": f"Bearer {token}", "If-Match": f'"{version}"'})


@needs_haproxy
@needs_store
def test_failover_keeps_every_acknowledged_edit(cluster):
    hap, daemons, _redis = cluster
    http = requests.Session()
    r = http.post(hap.url + "/v1/sessions", json={}, timeout=10)
    assert r.status_code == 201, r.text
    sid, token = r.json()["id"], r.json()["token"]
    auth = {"Authorization": f"Bearer {token}"}
    base = f"{hap.url}/v1/sessions/{sid}"
    r = http.put(base + "/complex", json=TWO_TETS, headers=auth, timeout=60)
    assert r.status_code == 200, r.text
    version = r.json()["version"]
    positions = [list(map(float, p)) for p in TWO_TETS["vertices"]]
    node = r.headers["X-Subdivd-Node"]
    for i in range(20):
        k = i % 5
        p = [c + 0.01 * (i + 1) * (1 if (i + c_i) % 2 else -1)
             for c_i, c in enumerate(TWO_TETS["vertices"][k])]
        r = _patch(http, base, token, version, [{"index": k, "position": p}])
        assert r.status_code == 200, (i, r.text)
        assert r.headers["X-Subdivd-Node"] == node, "a session's requests went to two daemons"
        version = r.json()["version"]
        positions[k] = p
    before = http.get(base + "/levels/2", params={"format": "json"}, headers=auth, timeout=60)
    assert before.status_code == 200, before.text
    assert before.json()["version"] == version

    victim = daemons[int(node[1:]) - 1]
    victim.proc.kill()
    victim.proc.wait()

    t0 = time.time()
    r = http.get(base + "/complex", headers=auth, timeout=60)
    assert r.status_code == 200, r.text + "\n" + hap.log()
    assert r.headers["X-Subdivd-Node"] != node
    assert r.headers.get("ETag") == f'"{version}"'
    doc = r.json()
    assert doc["vertices"] == positions
    assert doc.get("version", version) == version
    after = http.get(base + "/levels/2", params={"format": "json"}, headers=auth, timeout=60)
    assert after.status_code == 200, after.text
    assert after.json()["vertices"] == before.json()["vertices"]
    assert after.json()["version"] == version
    print(f"failover: first answer from the survivor after {time.time() - t0:.2f} s")
    # and editing goes on there
    r = _patch(http, base, token, version, [{"index": 0, "position": [0.5, 0.5, -0.5]}])
    assert r.status_code == 200, r.text
    assert r.json()["version"] == version + 1


# a cube cut into the 6 tetrahedra around its diagonal 0-7: level 6 is 6 * 8^6 tetrahedra, a
# download of about 55 MB in VTU, more than the socket buffers between the daemon, HAProxy and
# the client hold, so the daemon is still sending it while the client does not read
KUHN_CUBE = {"vertices": [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)],
             "simplices": [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                           [0, 4, 6, 7]]}


@needs_haproxy
@needs_store
def test_sigterm_drains_behind_haproxy(cluster):
    """docs/DEPLOY.md "Stopping a daemon": SIGTERM on the daemon serving a session while a
    download of it is in flight. The daemon stops listening (HAProxy sends the session's next
    requests to the other daemon, which loads it from redis: edits go on, 200), the download
    finishes whole, and only then the daemon exits, 0, with nothing cut short."""
    hap, daemons, _redis = cluster
    http = requests.Session()
    r = http.post(hap.url + "/v1/sessions", json={}, timeout=10)
    sid, token = r.json()["id"], r.json()["token"]
    auth = {"Authorization": f"Bearer {token}"}
    base = f"{hap.url}/v1/sessions/{sid}"
    r = http.put(base + "/complex", json=KUHN_CUBE, headers=auth, timeout=60)
    assert r.status_code == 200, r.text
    version, node = r.json()["version"], r.headers["X-Subdivd-Node"]
    victim = daemons[int(node[1:]) - 1]

    download = requests.get(base + "/levels/6", params={"format": "vtu"}, headers=auth,
                            stream=True, timeout=120)
    assert download.status_code == 200 and download.headers["X-Subdivd-Node"] == node
    length = int(download.headers["Content-Length"])
    first = download.raw.read(65536)   # the rest waits in the daemon until it is read
    victim.proc.terminate()
    time.sleep(0.5)
    assert victim.alive(), "SIGTERM did not wait for the download in flight:\n" + \
        "\n".join(victim.log_lines[-5:])
    for i in range(6):   # meanwhile the session is served (by the other daemon)
        r = _patch(http, base, token, version, [{"index": 7, "position": [1, 1, 1 + 0.01 * i]}])
        assert r.status_code == 200, (i, r.status_code, r.text)
        version = r.json()["version"]
    assert r.headers["X-Subdivd-Node"] != node
    body = first + download.raw.read()
    assert len(body) == length, f"the download was cut at {len(body)} of {length} bytes"
    assert victim.proc.wait(30) == 0
    victim.stop()
    assert not any("cut short" in line for line in victim.log_lines), victim.log_lines[-5:]
    assert any(line.endswith(" stopped") for line in victim.log_lines)


@needs_store
def test_two_daemons_one_if_match_one_winner(tmp_path):
    with two_daemons(tmp_path) as (daemons, http, sid, token, auth, version):
        # the other daemon knows the session (from redis)
        r = http[1].get(f"{daemons[1].url}/v1/sessions/{sid}", headers=auth, timeout=10)
        assert r.status_code == 200 and r.json()["version"] == version, r.text
        for rnd in range(10):
            out = at_once(lambda k: _patch(
                http[k], f"{daemons[k].url}/v1/sessions/{sid}", token, version,
                [{"index": 4, "position": [1 + 0.01 * rnd, 1 + 0.02 * k, 1]}]))
            codes = sorted(o.status_code for o in out)
            assert codes == [200, 412], (rnd, [(o.status_code, o.text) for o in out])
            winner = next(o for o in out if o.status_code == 200)
            assert winner.json()["version"] == version + 1
            version += 1
        # both agree on the result
        docs = [http[k].get(f"{daemons[k].url}/v1/sessions/{sid}/complex", headers=auth,
                            timeout=60) for k in range(2)]
        assert [d.status_code for d in docs] == [200, 200]
        assert docs[0].json()["vertices"] == docs[1].json()["vertices"]
        assert docs[0].headers["ETag"] == docs[1].headers["ETag"] == f'"{version}"'


@needs_store
def test_two_daemons_changes_without_if_match_are_both_made(tmp_path):
    """docs/API.md: a change without If-Match is not checked against a version. Two such changes
    of one session through two daemons at the same moment are both made (200, versions v+1 and
    v+2): the one the store refuses first is made again on the session as stored, never a 412."""
    with two_daemons(tmp_path) as (daemons, http, sid, token, auth, version):
        weights = ["warren", "loop"]
        for rnd in range(12):
            out = at_once(lambda k: http[k].put(f"{daemons[k].url}/v1/sessions/{sid}/rules",
                                                headers=auth, timeout=60,
                                                json={"surface_weights": weights[k]}))
            assert [o.status_code for o in out] == [200, 200], [(o.status_code, o.text) for o in out]
            assert sorted(o.json()["version"] for o in out) == [version + 1, version + 2]
            version += 2
            last = max(range(2), key=lambda k: out[k].json()["version"])
            for k in range(2):   # both daemons show the later change
                c = http[k].get(f"{daemons[k].url}/v1/sessions/{sid}/complex", headers=auth,
                                timeout=60)
                assert c.headers["ETag"] == f'"{version}"'
                assert c.json()["rules"]["surface_weights"] == weights[last]
        # embedded models too: each daemon puts one of its own, both are kept
        model = {"vertices": [[0.2, 0.2, 0.2], [0.3, 0.2, 0.25]], "level": 1}
        for rnd in range(6):
            out = at_once(lambda k: http[k].put(
                f"{daemons[k].url}/v1/sessions/{sid}/embedded/m{rnd}_{k}", headers=auth,
                json=model, timeout=60))
            assert [o.status_code for o in out] == [200, 200], [(o.status_code, o.text) for o in out]
            version += 2
            for k in range(2):
                r = http[k].get(f"{daemons[k].url}/v1/sessions/{sid}/embedded", headers=auth,
                                timeout=60)
                names = {e["name"] for e in r.json()["embedded"]}
                assert {f"m{rnd}_0", f"m{rnd}_1"} <= names, names
            if rnd % 2:   # at most 8 models: the two of this round and the one before go
                for n in (f"m{rnd}_0", f"m{rnd}_1", f"m{rnd - 1}_0", f"m{rnd - 1}_1"):
                    assert http[0].delete(f"{daemons[0].url}/v1/sessions/{sid}/embedded/{n}",
                                          headers=auth, timeout=60).status_code == 204
                version += 4


@needs_store
def test_two_daemons_edits_with_if_match_star_are_both_made(tmp_path):
    """docs/DEPLOY.md: a change sent with `If-Match: *` names no version, so one whose
    compare-and-set another daemon's change won is made again on the session as stored. An edit
    (PATCH, which takes `*` in place of a version) too: two sent at once through two daemons are
    both answered 200 (versions v+1 and v+2) and both moves are kept, as on one daemon."""
    with two_daemons(tmp_path) as (daemons, http, sid, token, auth, version):
        star = dict(auth, **{"If-Match": "*"})
        for rnd in range(16):
            spots = [[0.01 * rnd, -0.01 * rnd, 0], [1 + 0.01 * rnd, 1, 1 - 0.01 * rnd]]
            out = at_once(lambda k: http[k].patch(
                f"{daemons[k].url}/v1/sessions/{sid}/control-points", headers=star, timeout=60,
                json={"moves": [{"index": 4 * k, "position": spots[k]}]}))
            assert [o.status_code for o in out] == [200, 200], [(o.status_code, o.text) for o in out]
            assert sorted(o.json()["version"] for o in out) == [version + 1, version + 2]
            version += 2
            for k in range(2):   # both daemons hold both moves
                c = http[k].get(f"{daemons[k].url}/v1/sessions/{sid}/complex", headers=auth,
                                timeout=60)
                assert c.headers["ETag"] == f'"{version}"'
                assert [c.json()["vertices"][i] for i in (0, 4)] == spots


@needs_store
def test_requests_at_once_on_a_copy_behind_are_answered_from_the_stored_state(tmp_path):
    """docs/DEPLOY.md: a daemon whose resident copy is behind reads the stored session again
    before it answers. Several requests reaching it at once (a client's reads and edits, after
    HAProxy moved the session to it) are all answered from the stored state, not only the first:
    the others, which find the first checking, look again once it is done."""
    with two_daemons(tmp_path) as (daemons, http, sid, token, auth, version):
        url = [f"{d.url}/v1/sessions/{sid}" for d in daemons]
        bad = []
        for rnd in range(12):
            r = http[1].get(url[1] + "/complex", headers=auth, timeout=60)   # resident on n2
            assert r.status_code == 200 and r.headers["ETag"] == f'"{version}"', r.text
            for i in range(3):                                            # n1 moves on
                r = _patch(http[0], url[0], token, version,
                           [{"index": 4, "position": [1, 1, 1 + 0.01 * (3 * rnd + i)]}])
                assert r.status_code == 200, r.text
                version = r.json()["version"]
            at = version

            def one(k):
                if k % 2:
                    return requests.get(url[1] + "/complex", headers=auth, timeout=60)
                return requests.patch(url[1] + "/control-points", timeout=60,
                                      json={"moves": [{"index": 4, "position": [1, 1, 2 + 0.1 * k]}]},
                                      headers=dict(auth, **{"If-Match": f'"{at}"'}))
            out = at_once(one, 6)
            got = [(o.request.method, o.status_code, o.headers.get("ETag")) for o in out]
            gets = [g for g in got if g[0] == "GET"]
            patches = [g for g in got if g[0] == "PATCH"]
            # the reads show the stored version (or one of the edits sent with them), never the
            # one n2 held; of the edits naming the stored version exactly one is made
            if any(g[1] != 200 or int(g[2].strip('"')) < at for g in gets) or \
                    sorted(p[1] for p in patches) != [200, 412, 412]:
                bad.append((rnd, at, got))
            version = at + 1
        assert not bad, bad


@needs_store
def test_a_ttl_given_through_one_daemon_holds_on_the_other(tmp_path):
    """PATCH /v1/sessions/{id} {"ttl_s"} through one daemon: the other, which holds the session
    resident with its old TTL, takes the new one at its next request (as it takes a newer
    version), so it neither keeps the session beyond it nor lets it go before."""
    import datetime
    with two_daemons(tmp_path) as (daemons, http, sid, token, auth, version):
        url = [f"{d.url}/v1/sessions/{sid}" for d in daemons]

        def expires_in(k):
            r = http[k].get(url[k], headers=auth, timeout=10)
            assert r.status_code == 200, r.text
            at = datetime.datetime.strptime(r.json()["expires_at"], "%Y-%m-%dT%H:%M:%SZ")
            return at.replace(tzinfo=datetime.timezone.utc).timestamp() - time.time()
        assert expires_in(1) > 3000                      # resident on the second, TTL 3600
        r = http[0].patch(url[0], json={"ttl_s": 2}, headers=auth, timeout=10)
        assert r.status_code == 200 and r.json()["ttl_s"] == 2, r.text
        assert expires_in(1) <= 3                        # the second has the new TTL
        time.sleep(3.5)
        assert http[1].get(url[1], headers=auth, timeout=10).status_code == 404
        r = http[0].patch(url[0], json={"ttl_s": 600}, headers=auth, timeout=10)
        assert r.status_code == 404, r.text


@contextlib.contextmanager
def two_daemons(tmp_path):
    """Two daemons on one redis and a session with TWO_TETS made through the first:
    (daemons, their HTTP sessions, id, token, auth header, version)."""
    redis = RedisServer(tmp_path).start()
    daemons = []
    try:
        daemons = [Daemon("--store", redis.url) for _ in range(2)]
        http = [requests.Session(), requests.Session()]
        r = http[0].post(daemons[0].url + "/v1/sessions", json={}, timeout=10)
        assert r.status_code == 201, r.text
        sid, token = r.json()["id"], r.json()["token"]
        auth = {"Authorization": f"Bearer {token}"}
        r = http[0].put(f"{daemons[0].url}/v1/sessions/{sid}/complex", json=TWO_TETS,
                        headers=auth, timeout=60)
        assert r.status_code == 200, r.text
        yield daemons, http, sid, token, auth, r.json()["version"]
    finally:
        for d in daemons:
            d.stop()
        redis.stop()


def at_once(call, n=2):
    """call(k) for k < n from n threads let go at the same moment; their results in order."""
    start, out = threading.Barrier(n), [None] * n

    def run(k):
        start.wait()
        out[k] = call(k)
    th = [threading.Thread(target=run, args=(k,)) for k in range(n)]
    for t in th:
        t.start()
    for t in th:
        t.join(60)
    return out


@needs_haproxy
@needs_store
def test_a_daemon_full_of_event_streams_queues_requests_in_haproxy(tmp_path):
    """Event streams hold a daemon's connections for as long as they are open. HAProxy opens at
    most `maxconn` connections to a daemon (its --max-connections minus --connection-reserve,
    over both backends): a request past them waits in HAProxy's queue and is served when a stream
    ends, or after `timeout queue` is a 503 not-ready problem with Retry-After — where the daemon
    would have refused the connection, a 502 page clients do not retry. Daemons of 10
    connections, 2 kept in reserve: maxconn 6 + 2."""
    redis = RedisServer(tmp_path).start()
    daemons, hap, streams = [], None, []
    try:
        daemons = [Daemon("--store", redis.url, "--max-connections", "10",
                          "--connection-reserve", "2", "--sse-heartbeat", "1") for _ in range(2)]
        hap = HAProxy(tmp_path, [_addr(d) for d in daemons], maxconn=(6, 2), queue="3s")
        r = requests.post(hap.url + "/v1/sessions", json={}, timeout=10)
        assert r.status_code == 201, r.text
        sid, auth = r.json()["id"], {"Authorization": f"Bearer {r.json()['token']}"}
        base = f"{hap.url}/v1/sessions/{sid}"
        for _ in range(6):   # the daemon's six connections of this backend, held
            st = http.client.HTTPConnection("127.0.0.1", hap.port, timeout=30)
            st.request("GET", f"/v1/sessions/{sid}/events", headers=auth)
            assert st.getresponse().status == 200
            streams.append(st)
        # a seventh request waits: no answer while the streams are open, then 503 in the
        # daemons' form
        t0 = time.monotonic()
        r = requests.get(base, headers=auth, timeout=30)
        waited = time.monotonic() - t0
        assert r.status_code == 503 and waited >= 2.5, (r.status_code, waited, r.text)
        assert_retry_problem(r, 503, "not-ready")
        # queued again, and served as soon as one stream ends
        out = {}
        th = threading.Thread(target=lambda: out.update(r=requests.get(base, headers=auth,
                                                                       timeout=30)))
        th.start()
        time.sleep(0.5)
        assert "r" not in out, "answered while every connection of the daemon was held"
        streams.pop().close()   # HAProxy finds it closed at the next heartbeat (1 s)
        th.join(10)
        assert out["r"].status_code == 200, out["r"].text
        # the streams held are still open and the daemon is served through the other backend
        assert requests.get(hap.url + "/healthz", timeout=10).status_code == 200
    finally:
        for st in streams:
            st.close()
        if hap:
            hap.stop()
        for d in daemons:
            d.stop()
        redis.stop()


@needs_haproxy
def test_a_daemon_that_closes_without_an_answer_is_a_502_problem(tmp_path):
    """A daemon that dies while a request is on its way (here a stand-in that answers /readyz
    and closes every other connection unanswered): HAProxy's 502 in the daemons' form, a
    problem+json of type bad-gateway, without Retry-After (a change may have been made)."""
    import socket
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(64)
    port = srv.getsockname()[1]
    stop = threading.Event()

    def serve():
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                c, _ = srv.accept()
            except OSError:
                continue
            with c:
                c.settimeout(2)
                try:
                    head = c.recv(65536)
                except OSError:
                    continue
                if head.startswith(b"GET /readyz "):
                    c.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
    th = threading.Thread(target=serve, daemon=True)
    th.start()
    hap = None
    try:
        hap = HAProxy(tmp_path, [f"127.0.0.1:{port}"] * 2)
        r = requests.get(hap.url + "/v1/sessions/" + "ab" * 16, timeout=30)
        assert r.status_code == 502, (r.status_code, r.text)
        assert r.headers["Content-Type"] == "application/problem+json", r.headers
        assert r.json()["type"] == "/errors/bad-gateway" and r.json()["status"] == 502, r.text
        assert "Retry-After" not in r.headers
    finally:
        stop.set()
        if hap:
            hap.stop()
        th.join(5)
        srv.close()
