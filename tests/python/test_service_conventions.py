"""Service conventions: every problem `type` resolves (GET /errors/<slug>, made from the one table
of docs/SERVICE.md "Errors", which names every slug the code reports), `subdivd --version`,
access-log lines that name the route pattern and the problem type, and the /metrics series of
latency by route and status and compute seconds by kind."""
import re
import subprocess
import time

import requests

from conftest import REPO
from daemon import SUBDIVD, Daemon, Session

TET = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "simplices": [[0, 1, 2, 3]]}


def table_slugs():
    """{slug: status} of the table in docs/SERVICE.md, "Errors"."""
    text = (REPO / "docs" / "SERVICE.md").read_text(encoding="utf-8")
    section = text.split("\n## Errors\n", 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in section.splitlines():
        m = re.match(r"\| (\d{3}) \| (.*?) \|", line)
        if m:
            for slug in re.findall(r"`([a-z-]+)`", m.group(2)):
                assert slug not in out, f"{slug} is in two rows"
                out[slug] = int(m.group(1))
    return out


FAIL_CALL = re.compile(r"(?:api_fail(?:_at)?|http_fail)\([^,]+,\s*(\d{3}),\s*\"([a-z-]+)\"")


def c_sources():
    """(path, text) of the C sources that answer requests (api/, server/)."""
    for path in list((REPO / "api").glob("*.c")) + list((REPO / "server").glob("*.c")):
        yield path, path.read_text(encoding="utf-8")


def code_slugs():
    """The slugs the C sources report: api_fail*/http_fail calls and literal /errors/ types."""
    found = set()
    for path, src in c_sources():
        found |= {m.group(2) for m in FAIL_CALL.finditer(src)}
        found |= set(re.findall(r"/errors/([a-z][a-z-]+)", src))
        if "api_fail_limit(" in src:
            found.add("limit-exceeded")
    return found


def test_the_table_names_every_slug_of_the_code():
    missing = code_slugs() - set(table_slugs())
    assert not missing, f"slugs reported by the code without a row in docs/SERVICE.md: {missing}"


def test_the_code_answers_each_slug_with_the_status_of_its_row():
    """A slug is one kind of problem with one status (its row, its /errors/ page): a call that
    reports it with another status contradicts the page a client is sent to."""
    table, wrong = table_slugs(), []
    for path, src in c_sources():
        for m in FAIL_CALL.finditer(src):
            if m.group(2) in table and table[m.group(2)] != int(m.group(1)):
                wrong.append(f"{path.name}:{src[:m.start()].count(chr(10)) + 1} {m.group(1)} "
                             f"{m.group(2)} (its row: {table[m.group(2)]})")
    assert not wrong, wrong


def test_every_type_resolves():
    d = Daemon()
    try:
        slugs = table_slugs()
        assert len(slugs) > 40
        for slug, status in slugs.items():
            r = requests.get(f"{d.url}/errors/{slug}", timeout=10)
            assert r.status_code == 200, (slug, r.text)
            assert r.headers["Content-Type"] == "text/markdown; charset=utf-8"
            assert r.text.startswith(f"# {slug}\n") and f"**{status} " in r.text, r.text
            assert f'"type": "/errors/{slug}"' in r.text
        for bad in ("nope", "Invalid-Complex", "x" * 39, "y" * 60, "invalid-complex.md"):
            r = requests.get(f"{d.url}/errors/{bad}", timeout=10)
            assert r.status_code == 404, bad
            assert r.headers["Content-Type"] == "application/problem+json"
            assert r.json()["type"] == "/errors/not-found"
        assert requests.get(f"{d.url}/errors/", timeout=10).status_code == 404
        r = requests.post(f"{d.url}/errors/busy", timeout=10)
        assert r.status_code == 405 and r.json()["type"] == "/errors/method-not-allowed"
        assert "GET" in r.headers["Allow"]
        # a real answer's type, resolved against the daemon's URL
        s = Session(d)
        p = s.put_complex({"vertices": [[0, 0, 0]], "simplices": [[0, 7]]})
        assert p.status_code == 422
        page = requests.get(d.url + p.json()["type"], timeout=10)
        assert page.status_code == 200 and "**422 Unprocessable Content**" in page.text
    finally:
        d.stop()


def test_version():
    r = subprocess.run([str(SUBDIVD), "--version"], capture_output=True, encoding="utf-8")
    assert r.returncode == 0 and re.fullmatch(r"subdivd \d+\.\d+\.\d+\n", r.stdout)
    r = subprocess.run([str(SUBDIVD), "--help"], capture_output=True, encoding="utf-8")
    assert "--version" in r.stdout


def test_log_lines_and_metrics():
    d = Daemon()
    try:
        s = Session(d)
        assert s.put_complex(TET).status_code == 200
        assert s.level(1, format="json").status_code == 200
        assert s.req("GET", "/levels/2/stats?x=1").status_code == 400
        deadline = time.time() + 5
        while time.time() < deadline and sum(s.id in l for l in d.log_lines) < 4:
            time.sleep(0.02)
        lines = [l for l in d.log_lines if s.id in l]
        assert any(l.endswith(" route=/v1/sessions/{id}/complex") and " PUT " in l for l in lines), lines
        bad = [l for l in lines if "/stats" in l]
        assert len(bad) == 1 and bad[0].endswith(
            " 400 " + bad[0].split(" 400 ")[1].split(" route=")[0]
            + " route=/v1/sessions/{id}/levels/{L}/stats type=/errors/unknown-parameter"), bad
        assert "?" not in "".join(lines) and s.token not in "\n".join(d.log_lines)
        # health checks that pass are not logged at info (a balancer sends one a second)
        for path in ("/healthz", "/readyz"):
            assert requests.get(d.url + path, timeout=10).status_code == 200
        assert requests.get(d.url + "/v1/sessions/" + s.id + "/nothing", timeout=10).status_code
        deadline = time.time() + 5
        while time.time() < deadline and not any("/nothing" in l for l in d.log_lines):
            time.sleep(0.02)
        assert any("/nothing" in l for l in d.log_lines)     # logged after the two checks
        assert not [l for l in d.log_lines if " /healthz " in l or " /readyz " in l], d.log_lines
        text = requests.get(d.url + "/metrics", timeout=10).text
        lab = 'route="/v1/sessions/{id}/levels/{L}",method="GET",status="200"'
        assert re.search(r'^subdivd_request_duration_seconds_bucket\{' + re.escape(lab)
                         + r',le="\+Inf"\} 1$', text, re.M), text
        assert re.search(r'^subdivd_request_duration_seconds_count\{' + re.escape(lab) + r'\} 1$',
                         text, re.M)
        assert re.search(r'^subdivd_request_duration_seconds_count\{route="/v1/sessions/\{id\}/'
                         r'levels/\{L\}/stats",method="GET",status="400"\} 1$', text, re.M)
        for kind in ("complex", "level"):
            m = re.search(r'^subdivd_compute_seconds_total\{kind="%s"\} ([\d.e+-]+)$' % kind, text, re.M)
            assert m and float(m.group(1)) > 0, (kind, text)
            assert re.search(r'^subdivd_compute_total\{kind="%s"\} [1-9]\d*$' % kind, text, re.M)
        # every documented metric name is served
        doc = (REPO / "docs" / "SERVICE.md").read_text(encoding="utf-8")
        for name in ("subdivd_request_duration_seconds", "subdivd_compute_seconds_total",
                     "subdivd_compute_total"):
            assert name in doc and f"# TYPE {name} " in text
        # and every metric served is in the list of "Health and metrics"
        section = doc.split("## Health and metrics", 1)[1].split("\n## ", 1)[0]
        served = re.findall(r"^# TYPE (\w+) ", text, re.M)
        assert served and not [n for n in served if f"`{n}" not in section], served
    finally:
        d.stop()
