"""``fovexp monitor [RESULTS]``: the operator's live view of the sessions under a results folder,
in a browser (docs/EXPERIMENT.md, "The operator's live view"). ``fovexp run --monitor`` starts
it beside a session (:func:`start_beside`)."""

from __future__ import annotations

import argparse
import logging
import os
import secrets
import socket
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from fovexp import FovexpError
from fovexp.results.limits import add_limit_options, limits_from_args

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: the monitor's niceness above the session's when ``fovexp run --monitor`` starts it
MONITOR_NICE = 10
MISSING_EXTRA = ("fovexp monitor needs starlette and uvicorn: pip install 'fovexp[monitor]'")


class _SayHandler(logging.Handler):
    """The server's log lines (a refused request: :data:`fovexp.monitor.server.LOG`), said
    where the monitor's own lines go (stderr; the session's console under ``fovexp run
    --monitor``)."""

    def __init__(self, say: Any) -> None:
        super().__init__(logging.INFO)
        self.say = say

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.say(record.getMessage())
        except Exception:
            self.handleError(record)


def require_server() -> None:
    """Raise one line naming the ``monitor`` extra when its packages are missing."""
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as exc:
        raise FovexpError(f"{MISSING_EXTRA} ({exc})") from None


def _configure(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("results", nargs="?", type=Path, default=Path("results"),
                   help="the results folder the sessions write to (default: results)")
    p.add_argument("--host", default=None,
                   help=f"the address to serve (default {DEFAULT_HOST}: this machine only); "
                        "another, such as 0.0.0.0 (the lab's network), requires the random "
                        "token printed at the start with every request")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"the port (default {DEFAULT_PORT}; 0: any free one)")
    p.add_argument("--report", type=Path, default=None, metavar="DIR",
                   help="the folder fovexp analyze wrote its report to, linked from finished "
                        "sessions (default: report/ beside the results folder, when it is there)")
    add_limit_options(p)
    p.set_defaults(func=monitor_command)
    return p


def add_monitor_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``monitor`` sub-command to ``fovexp``'s parser."""
    p = sub.add_parser(
        "monitor", help="watch running sessions in a browser (read-only)",
        description="Serve a read-only page showing every session running under RESULTS "
                    "(trial counter and ETA, the gaze around the cross against the blanking "
                    "window, the current trial against the exclusion rules R11-R13, the "
                    "tracker's state and quality) and the finished ones, with a link to "
                    "fovexp analyze's report. It reads the files the runner writes and "
                    "nothing else.")
    return _configure(p)


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        why = "in use (another fovexp monitor?)" if exc.errno in (98, 48, 10048) else exc.strerror
        raise FovexpError(f"cannot serve {host}:{port}: {why}; choose another with --port") \
            from None
    sock.listen(64)
    sock.set_inheritable(True)
    return sock


def _lan_name(host: str) -> str:
    """A name other machines can use for this one when serving ``host``."""
    if host not in ("0.0.0.0", "::", ""):
        return host
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # a documentation address: nothing is sent
            return str(s.getsockname()[0])
    except OSError:
        return socket.gethostname()


def serve(results: Path, host: str | None = None, port: int = DEFAULT_PORT,
          report: Path | None = None, limits: Any = None,
          ready: threading.Event | None = None, say: Any = None) -> int:
    """Serve until interrupted (Ctrl-C, SIGTERM). Without ``host``: 127.0.0.1, no token; with
    one that is not a loopback address, a random token every request must carry."""
    require_server()
    import uvicorn

    from .server import LOG, create_app, is_loopback
    from .view import ResultsView

    say = say or (lambda t: print(t, file=sys.stderr, flush=True))
    host = host or DEFAULT_HOST
    if report is None:
        guess = Path(results).resolve().parent / "report"
        report = guess if (guess / "report.html").is_file() else None
    view = ResultsView(results, limits=limits, report=report)
    local = is_loopback(host)
    token = None if local else secrets.token_urlsafe(18)
    stopping = threading.Event()
    app = create_app(view, token=token, loopback_only=local, stopping=stopping)
    sock = _bind(host, port)
    actual = sock.getsockname()[1]
    shown = host if ":" not in host else f"[{host}]"
    if local:
        say(f"fovexp monitor: {view.root} at http://{shown}:{actual}/ (this machine only; "
            "read-only; Ctrl-C stops)")
    else:
        say(f"fovexp monitor: {view.root} at http://{_lan_name(host)}:{actual}/?token={token} "
            "(the lab's network: every request needs this token; read-only; Ctrl-C stops)")

    class Server(uvicorn.Server):
        def handle_exit(self, sig: int, frame: Any) -> None:  # streams end at once
            stopping.set()
            super().handle_exit(sig, frame)

    config = uvicorn.Config(app, log_level="warning", access_log=False, proxy_headers=False,
                            server_header=False, limit_concurrency=64, timeout_keep_alive=5,
                            timeout_graceful_shutdown=2, h11_max_incomplete_event_size=16384,
                            lifespan="off")
    server = Server(config)
    if ready is not None:
        threading.Thread(target=_wait_started, args=(server, ready), daemon=True).start()
    said = _SayHandler(say)
    LOG.addHandler(said)
    try:
        server.run(sockets=[sock])
    finally:
        LOG.removeHandler(said)
        stopping.set()
        sock.close()
    return 0


def _wait_started(server: Any, ready: threading.Event) -> None:
    import time

    while not server.started and not server.should_exit:
        time.sleep(0.02)
    ready.set()


def monitor_command(args: argparse.Namespace) -> int:
    if args.port < 0 or args.port > 65535:
        raise FovexpError(f"--port {args.port}: 0 to 65535")
    if not Path(args.results).is_dir():
        raise FovexpError(f"{args.results}: no such results folder")
    if args.report is not None and not (args.report / "report.html").is_file():
        raise FovexpError(f"--report {args.report}: no report.html there (fovexp analyze "
                          f"RESULTS --out {args.report} writes it)")
    return serve(args.results, args.host, args.port, args.report, limits_from_args(args))


def start_beside(results: Path, host: str | None, port: int = DEFAULT_PORT,
                 ) -> subprocess.Popen[bytes]:
    """``fovexp run --monitor``: ``fovexp monitor`` in a process of its own, at a lower
    priority (it shares no memory with the session; its output goes to the same console)."""
    require_server()
    Path(results).mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "fovexp", "monitor", str(results), "--port", str(port)]
    if host:
        cmd += ["--host", host]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                            creationflags=getattr(subprocess, "BELOW_NORMAL_PRIORITY_CLASS", 0))
    try:  # below the session (Windows: the creation flag above)
        os.setpriority(os.PRIO_PROCESS, proc.pid, os.getpriority(os.PRIO_PROCESS, 0)
                       + MONITOR_NICE)
    except (AttributeError, OSError):
        pass
    return proc


def stop_beside(proc: subprocess.Popen[bytes]) -> None:
    """End the monitor :func:`start_beside` started."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main(argv: list[str] | None = None) -> int:
    """``python -m fovexp.monitor``: the same as ``fovexp monitor``."""
    args = _configure(argparse.ArgumentParser(prog="python -m fovexp.monitor")).parse_args(argv)
    try:
        return monitor_command(args)
    except FovexpError as exc:
        print(f"fovexp monitor: error: {exc}", file=sys.stderr)
        return 2


__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "MISSING_EXTRA", "add_monitor_parser",
           "monitor_command", "require_server", "serve", "start_beside", "stop_beside"]
