"""``fovexp monitor``'s server (fovexp.monitor.server, .cli): the page and its data, events
within a second of a change on disk, and hostile requests refused: other methods, bodies,
over-long addresses, a foreign Host, a missing or wrong token, paths out of the results or
report folder."""

from __future__ import annotations

import json
import logging
import re
import socket
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the monitor extra is not installed")
httpx = pytest.importorskip("httpx2", reason="httpx2 is not installed (the test extra)")

from starlette.testclient import TestClient  # noqa: E402

from fovexp.monitor.server import (  # noqa: E402
    MAX_LOGGED_PATH,
    TOKEN_COOKIE,
    create_app,
    redacted_target,
)
from fovexp.monitor.view import ResultsView  # noqa: E402
from fovexp.results.limits import TrialLimits  # noqa: E402

from monitor_helpers import MonitorProcess, live, session_file, write_live_file  # noqa: E402

SID = "20261124-101010"
KEY = f"calibration-sk/P01/{SID}"


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    f = tmp_path / "results" / "calibration-sk" / "P01"
    session_file(f, SID)
    write_live_file(f, live(SID))
    return tmp_path / "results"


@pytest.fixture()
def report(tmp_path: Path) -> Path:
    r = tmp_path / "report"
    (r / "figures").mkdir(parents=True)
    (r / "report.html").write_text("<html><img src='figures/a.png'></html>")
    (r / "figures" / "a.png").write_bytes(b"\x89PNG fake")
    (tmp_path / "secret.txt").write_text("not yours")
    return r


def client(root: Path, token: str | None = None, report: Path | None = None,
           loopback_only: bool = True, host: str = "127.0.0.1") -> TestClient:
    app = create_app(ResultsView(root, report=report), token=token, loopback_only=loopback_only)
    return TestClient(app, base_url=f"http://{host}:8765")


def test_the_page_and_its_data(root: Path, report: Path) -> None:
    c = client(root, report=report)
    page = c.get("/")
    assert page.status_code == 200 and "fovexp monitor" in page.text
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"
    assert page.headers["referrer-policy"] == "no-referrer"
    for asset in ("/static/monitor.js", "/static/monitor.css"):
        assert c.get(asset).status_code == 200
    # nothing on the page comes from elsewhere (labs are often offline)
    for name in ("index.html", "monitor.js", "monitor.css"):
        text = (Path(__file__).resolve().parents[2] / "fovexp/monitor/static" / name).read_text()
        assert "http://" not in text and "https://" not in text, name
    sessions = c.get("/api/sessions").json()["sessions"]
    assert [s["key"] for s in sessions] == [KEY] and sessions[0]["status"] == "running"
    v = c.get("/api/session", params={"key": KEY}).json()
    assert v["trial"]["position"] == 3
    assert v["limits"] == TrialLimits().as_dict()  # fovexp analyze's defaults
    assert c.get("/report/report.html").status_code == 200
    assert c.get("/report/figures/a.png").content == b"\x89PNG fake"
    assert "script-src 'none'" in c.get("/report/report.html").headers[
        "content-security-policy"]


@pytest.mark.parametrize("path", [
    "/api/session?key=../../../etc/passwd", "/api/session?key=calibration-sk/P01/..%2f..",
    "/api/session?key=calibration-sk%2FP01%2F..%2F..%2Fsecret", "/api/session?key=%2Fetc%2FP01%2Fx",
    "/api/stream?key=../../x", "/static/../server.py", "/static/%2e%2e/server.py",
    "/static/..%2fserver.py", "/report/../secret.txt", "/report/%2e%2e/secret.txt",
    "/report/..%2fsecret.txt", "/report/%2e%2e%2fsecret.txt", "/../secret.txt",
])
def test_paths_out_of_the_served_folders_are_refused(root: Path, report: Path,
                                                     path: str) -> None:
    r = client(root, report=report).get(path)
    assert r.status_code in (400, 404), (path, r.status_code)
    assert "not yours" not in r.text and "import" not in r.text


@pytest.mark.parametrize(("link", "target"), [
    pytest.param("leak.txt", "ABS/secret.txt", id="file-absolute"),
    pytest.param("figures/leak.txt", "../../secret.txt", id="file-relative"),
    pytest.param("figures/up", "ABS", id="folder"),
])
def test_symlinks_out_of_the_report_folder_are_refused(root: Path, report: Path, link: str,
                                                       target: str) -> None:
    """A symlink inside the report folder to a file, or a folder, outside it is not followed:
    /report serves what lies inside the folder once every link is resolved."""
    (report / link).symlink_to(target.replace("ABS", str(report.parent)))
    assert (report / link).exists()  # the link works on disk
    url = "/report/" + link + ("/secret.txt" if link.endswith("up") else "")
    r = client(root, report=report).get(url)
    assert r.status_code == 404, (url, r.status_code)
    assert "not yours" not in r.text


def test_no_report_folder(root: Path) -> None:
    r = client(root).get("/report/report.html")
    assert r.status_code == 404 and "--report" in r.text


@pytest.mark.parametrize(("method", "status"), [("POST", 405), ("PUT", 405), ("DELETE", 405),
                                                ("PATCH", 405), ("OPTIONS", 405)])
def test_it_is_read_only(root: Path, method: str, status: int) -> None:
    assert client(root).request(method, "/").status_code == status


def test_too_large_requests_are_refused(root: Path) -> None:
    c = client(root)
    assert c.request("GET", "/", content=b"x" * 10).status_code == 413
    assert c.request("GET", "/", content=b"x" * 10_000_000).status_code == 413
    assert c.get("/", headers={"transfer-encoding": "chunked"}).status_code == 413
    assert c.get("/api/session", params={"key": "a" * 5000}).status_code == 414
    assert c.get("/" + "a" * 2000).status_code == 414


def test_a_foreign_host_is_refused_on_the_loopback(root: Path) -> None:
    """A page elsewhere cannot read this one through a DNS name pointing at 127.0.0.1."""
    assert client(root, host="attacker.example").get("/").status_code == 400
    assert client(root, host="localhost").get("/").status_code == 200


def test_the_token(root: Path) -> None:
    token = "s3cret-token-abc"
    c = client(root, token=token, loopback_only=False, host="10.0.0.5")
    for path in ("/", "/api/sessions", "/static/monitor.js", f"/api/session?key={KEY}"):
        r = c.get(path)
        assert r.status_code == 403 and "token" in r.text, path
    assert c.get("/?token=wrong").status_code == 403
    assert c.get("/?token=" + token[:-1]).status_code == 403
    c.cookies.set(TOKEN_COOKIE, "wrong")
    assert c.get("/").status_code == 403
    c.cookies.clear()
    ok = c.get("/?token=" + token)
    assert ok.status_code == 200
    cookie = ok.headers["set-cookie"]
    assert f"{TOKEN_COOKIE}={token}" in cookie and "HttpOnly" in cookie
    assert "SameSite=Strict" in cookie
    # the page's own requests (its script, the report's figures) carry the cookie
    c.cookies.set(TOKEN_COOKIE, token)
    assert c.get("/static/monitor.js").status_code == 200
    assert c.get("/api/sessions").status_code == 200
    # the token is checked before anything else answers
    assert c.post("/?token=wrong").status_code == 405


TOKEN = "s3cret-token-abc"
#: the token's near misses: none opens the page, whether in the cookie or in ?token=
NEAR_MISSES = [
    pytest.param("", id="empty"), pytest.param(TOKEN[:-1], id="proper-prefix"),
    pytest.param(TOKEN[:4], id="short-prefix"),
    pytest.param(TOKEN[:-1] + "x", id="wrong-same-length"),
    pytest.param(TOKEN + "x", id="token-then-more"),
]


def _token_client(root: Path) -> TestClient:
    return client(root, token=TOKEN, loopback_only=False, host="10.0.0.5")


def _is_the_page(r: Any) -> bool:
    return r.status_code == 200 and "<title>fovexp monitor</title>" in r.text


@pytest.mark.parametrize("cookie", [
    pytest.param(None, id="no-cookie"), *NEAR_MISSES,
    pytest.param(f"other={TOKEN}", id="token-under-another-name"),
])
def test_a_cookie_other_than_the_token_is_refused(root: Path, cookie: str | None) -> None:
    """The token's cookie opens the page only when its value is exactly the token: no cookie,
    an empty one, a prefix of the token, a wrong token of its length, the token with more after
    it, or the token in another cookie, are refused (403) with the plain-text reason."""
    headers = {} if cookie is None else {
        "cookie": cookie if cookie.startswith("other=") else f"{TOKEN_COOKIE}={cookie}"}
    r = _token_client(root).get("/", headers=headers)
    assert r.status_code == 403 and "token" in r.text, (cookie, r.status_code)
    assert r.headers["content-type"].startswith("text/plain") and not _is_the_page(r)
    assert "set-cookie" not in r.headers


def test_the_token_in_the_cookie_opens_the_page(root: Path) -> None:
    """The cookie holding exactly the token opens the page (among other cookies too), and
    sets no new cookie."""
    for header in (f"{TOKEN_COOKIE}={TOKEN}", f"a=1; {TOKEN_COOKIE}={TOKEN}; b=2"):
        r = _token_client(root).get("/", headers={"cookie": header})
        assert _is_the_page(r), (header, r.status_code)
        assert "set-cookie" not in r.headers


@pytest.mark.parametrize("given", NEAR_MISSES)
def test_a_query_token_other_than_the_token_is_refused(root: Path, given: str) -> None:
    """``?token=`` opens the page only when it is exactly the token; a near miss is refused
    (403) and sets no cookie."""
    r = _token_client(root).get("/?token=" + given)
    assert r.status_code == 403 and "token" in r.text, (given, r.status_code)
    assert not _is_the_page(r) and "set-cookie" not in r.headers


def test_the_token_in_the_query_opens_the_page(root: Path) -> None:
    """``?token=`` holding exactly the token opens the page and sets the token's cookie."""
    r = _token_client(root).get("/?token=" + TOKEN)
    assert _is_the_page(r)
    assert r.headers["set-cookie"].startswith(f"{TOKEN_COOKIE}={TOKEN};")


#: a refused request's log line: time, client address, method, path, status and reason
REFUSED = re.compile(r"\Afovexp monitor: refused \d{4}-\d\d-\d\d \d\d:\d\d:\d\d "
                     r"(?P<client>\S+) (?P<method>\S+) (?P<path>\S+): (?P<why>.+)\Z")


def test_every_refused_request_is_logged_without_the_token(root: Path, report: Path,
                                                            caplog) -> None:
    """A missing or wrong token, a wrong method, a path or session that is not there, a
    foreign Host: one line each, the token's value (right or a near miss) never in it; an
    answered request logs nothing."""
    caplog.set_level(logging.WARNING, logger="fovexp.monitor")
    c = client(root, token=TOKEN, report=report, loopback_only=False, host="10.0.0.5")
    local = client(root, host="attacker.example")
    requests = [
        (c, "GET", "/api/sessions", 403),                      # no token
        (c, "GET", f"/?token={TOKEN[:-1]}", 403),              # a near miss
        (c, "GET", f"/?key=x&TOKEN={TOKEN[:4]}&a=1", 403),     # not the token's name
        (c, "POST", f"/?token={TOKEN}", 405),                  # another method
        (c, "GET", f"/api/session?key=../../etc&token={TOKEN}", 404),  # no such session
        (c, "GET", f"/report/%2e%2e/secret.txt?token={TOKEN}", 404),   # out of the folder
        (local, "GET", "/", 400),                              # a foreign Host
        (c, "GET", f"/?token={TOKEN}", 200),                   # answered: not logged
    ]
    for who, method, path, status in requests:
        assert who.request(method, path).status_code == status, path
    lines = [r.getMessage() for r in caplog.records if r.name == "fovexp.monitor"]
    assert len(lines) == len(requests) - 1, lines
    got = [REFUSED.match(line) for line in lines]
    assert all(got), lines
    assert [(m["client"], m["method"], m["path"]) for m in got] == [
        ("testclient:50000", "GET", "/api/sessions"),
        ("testclient:50000", "GET", "/?token=REDACTED"),
        ("testclient:50000", "GET", "/?key=x&TOKEN=REDACTED&a=1"),
        ("testclient:50000", "POST", "/?token=REDACTED"),
        ("testclient:50000", "GET", "/api/session?key=../../etc&token=REDACTED"),
        ("testclient:50000", "GET", "/report/%2e%2e/secret.txt?token=REDACTED"),
        ("testclient:50000", "GET", "/")]
    missing = ("403 this server needs the token it printed at its start: open the address "
               "with ?token=...")
    assert [m["why"] for m in got] == [
        missing, "403 wrong token", missing, "405 read-only: only GET and HEAD",
        "404 not found", "404 not found",
        "400 Host 'attacker.example:8765': this server answers 127.0.0.1 only"]
    assert TOKEN[:4] not in caplog.text  # nor any part of it


def test_a_logged_path_is_one_line_and_short() -> None:
    scope = {"raw_path": b"/a\nb" + b"x" * 1000, "query_string": b"tok%65n=abc&t=s3cret"}
    text = redacted_target(scope, token="s3cret")
    assert "\n" not in text and text.startswith("/a\\x0ab")
    assert text.endswith("... (1035 characters)")  # the escaped, redacted address's
    assert len(text) < MAX_LOGGED_PATH + 30
    assert redacted_target({"path": "/s3cret", "query_string": b"tok%65n=abc&t=s3cret"},
                           token="s3cret") == "/REDACTED?tok%65n=REDACTED&t=REDACTED"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _events(base: str, key: str | None, seconds: float, token: str | None = None) -> list[dict]:
    params = {"key": key} if key else {}
    if token:
        params["token"] = token
    out: list[dict] = []
    t_end = time.monotonic() + seconds
    with httpx.stream("GET", f"{base}/api/stream", params=params, timeout=10) as r:
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        for line in r.iter_lines():
            if line.startswith("data: "):
                out.append({**json.loads(line[6:]), "_t": time.monotonic()})
            if time.monotonic() > t_end:
                break
    return out


def test_the_stream_follows_the_disk_within_a_second(root: Path) -> None:
    mon = MonitorProcess([str(root), "--port", "0"])
    try:
        assert mon.base.startswith("http://127.0.0.1:") and mon.token is None
        f = root / "calibration-sk" / "P01"
        got: list[tuple[float, int]] = []
        t_write = 0.0
        with httpx.stream("GET", f"{mon.base}/api/stream", params={"key": KEY},
                          timeout=10) as r:
            for line in r.iter_lines():
                if not line.startswith("data: "):
                    continue
                data = json.loads(line[6:])
                got.append((time.monotonic(), data["view"]["trial"]["position"]))
                if len(got) == 1:
                    time.sleep(0.3)
                    t_write = time.monotonic()
                    write_live_file(f, live(SID, position=4, seq=2))
                if got[-1][1] == 4 or time.monotonic() - got[0][0] > 5:
                    break
        assert got[0][1] == 3 and got[-1][1] == 4
        assert got[-1][0] - t_write < 1.0  # the "within one second"
    finally:
        assert mon.stop() in (0, -15)


def test_the_lab_network_needs_the_token(root: Path) -> None:
    mon = MonitorProcess([str(root), "--host", "0.0.0.0", "--port", "0"])
    try:
        assert mon.token and len(mon.token) >= 20 and "every request needs" in mon.first_line
        port = mon.base.rsplit(":", 1)[1]
        base = f"http://127.0.0.1:{port}"
        assert httpx.get(base + "/").status_code == 403
        assert httpx.get(base + "/?token=nope").status_code == 403
        assert httpx.get(base + "/", params={"token": mon.token}).status_code == 200
        events = _events(base, None, 0.5, token=mon.token)
        assert events and events[0]["view"]["key"] == KEY
        assert httpx.get(base + "/nothing", params={"token": mon.token}).status_code == 404
    finally:
        mon.stop()
    # the operator's console: one line per refused request, the token never in it
    assert mon.proc.stderr is not None
    said = mon.proc.stderr.read()
    refused = [line for line in said.splitlines() if line.startswith("fovexp monitor: refused")]
    assert len(refused) == 3, said
    assert refused[0].endswith(" GET /: 403 this server needs the token it printed at its "
                               "start: open the address with ?token=...")
    assert refused[1].endswith(" GET /?token=REDACTED: 403 wrong token")
    assert refused[2].endswith(" GET /nothing?token=REDACTED: 404 not found")
    assert mon.token not in said


def test_command_errors(root: Path, tmp_path: Path) -> None:
    from experiment_helpers import run_cli

    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    try:
        port = busy.getsockname()[1]
        r = run_cli(["monitor", str(root), "--port", str(port)], cwd=tmp_path, timeout=60)
        assert r.returncode == 2 and f"127.0.0.1:{port}" in r.stderr and "in use" in r.stderr
    finally:
        busy.close()
    r = run_cli(["monitor", str(tmp_path / "none")], cwd=tmp_path, timeout=60)
    assert r.returncode == 2 and "no such results folder" in r.stderr
    r = run_cli(["monitor", str(root), "--report", str(tmp_path)], cwd=tmp_path, timeout=60)
    assert r.returncode == 2 and "no report.html" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
