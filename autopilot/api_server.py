"""The goal API's server: uvicorn on the autopilot's own event loop (:class:`ApiServer`, a
runtime service), guarded against slow or greedy clients (:class:`ConnectionLimits`: header
and idle timeouts, connection counts, a bounded request), over TLS when given a certificate;
and the token read from a file or the environment. The routes are :mod:`autopilot.api`'s."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot.runtime.ports import ConsolePort, GoalDeskPort
from autopilot.api import TOKEN_ENV, ApiSetupError, build_app, check_listen, is_loopback

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ConnectionLimits:
    """What one API server takes: connections open at once (in total and from one address),
    and how long a connection may take to send a request's headers (idle ones included;
    between requests uvicorn's keep-alive of 5 s applies). Beyond them a connection is closed
    at once: a client that opens thousands and never speaks costs the process a few file
    descriptors, not all of them, and the flight goes on."""

    max_connections: int = 256
    max_per_client: int = 32
    header_timeout_s: float = 10.0
    #: connections waiting in the kernel to be accepted, and so accepted per turn of the
    #: event loop (asyncio accepts up to the backlog at once): a burst of thousands is taken
    #: in slices, the loop turning between them, not in one stall of a third of a second
    backlog: int = 64


def _guarded_protocol(limits: ConnectionLimits):
    """uvicorn's HTTP protocol with :class:`ConnectionLimits` (a class per server)."""
    from uvicorn.protocols.http.h11_impl import H11Protocol

    live: dict = {}  # transport -> client address (WebSocket upgrades keep their transport)
    silent: dict = {}  # transports whose request's headers have not all come, oldest first
    refused = {"count": 0, "logged_s": -math.inf}

    class GuardedH11Protocol(H11Protocol):
        _header_timer: asyncio.TimerHandle | None = None

        def connection_made(self, transport) -> None:
            for gone in [t for t in live if t.is_closing()]:
                del live[gone]
                silent.pop(gone, None)
            super().connection_made(transport)
            address = self.client[0] if self.client else "?"
            if len(live) >= limits.max_connections and \
                    sum(1 for a in live.values() if a == address) < limits.max_per_client:
                # full: the connection waiting longest for its request's headers makes room
                # (idle sockets or slow headers from many addresses cannot lock out a client
                # that speaks)
                oldest = next((t for t in silent if not t.is_closing()), None)
                if oldest is not None:
                    silent.pop(oldest, None)
                    live.pop(oldest, None)
                    oldest.abort()
            if len(live) >= limits.max_connections or \
                    sum(1 for a in live.values() if a == address) >= limits.max_per_client:
                refused["count"] += 1
                now = time.monotonic()
                if now - refused["logged_s"] >= 10.0:  # one line per 10 s, never a flood
                    refused["logged_s"] = now
                    log.warning("goal API: connection from %s refused (%d open, at most %d, "
                                "%d from one address); %d refused so far", address, len(live),
                                limits.max_connections, limits.max_per_client,
                                refused["count"])
                transport.abort()
                return
            live[transport] = address
            self._arm_header_timer()

        def _arm_header_timer(self) -> None:
            silent[self.transport] = None
            if self._header_timer is None:
                self._header_timer = self.loop.call_later(limits.header_timeout_s,
                                                          self._header_timeout)

        def _between_requests(self) -> bool:
            return self.cycle is None or self.cycle.response_complete

        def _header_timeout(self) -> None:
            self._header_timer = None
            if self._between_requests() and not self.transport.is_closing():
                self.transport.abort()  # no request's headers in time (or none at all)

        def data_received(self, data: bytes) -> None:
            if self._between_requests():  # the start of a request: its headers have a deadline
                self._arm_header_timer()
            super().data_received(data)
            upgraded = self.transport.get_protocol() is not self  # now a WebSocket's
            if (upgraded or not self._between_requests()) and self._header_timer is not None:
                silent.pop(self.transport, None)
                self._header_timer.cancel()  # the headers came
                self._header_timer = None

        def connection_lost(self, exc) -> None:
            live.pop(self.transport, None)
            silent.pop(self.transport, None)
            if self._header_timer is not None:
                self._header_timer.cancel()
                self._header_timer = None
            super().connection_lost(exc)

    GuardedH11Protocol.live = live
    return GuardedH11Protocol


def check_tls(certfile: str, keyfile: str) -> None:
    """:class:`ApiSetupError` unless ``certfile`` and ``keyfile`` are a certificate (chain)
    and its private key in PEM (what uvicorn's ``--ssl-certfile``/``--ssl-keyfile`` take)."""
    import ssl

    for what, path in (("--api-tls-cert", certfile), ("--api-tls-key", keyfile)):
        if not Path(path).is_file():
            raise ApiSetupError(f"{what} {path}: no such file")
    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(certfile, keyfile)
    except (ssl.SSLError, OSError, ValueError) as exc:
        raise ApiSetupError(f"--api-tls-cert {certfile} / --api-tls-key {keyfile}: not a PEM "
                            f"certificate and its private key ({exc})") from None


def _raise_open_files_limit(wanted: int = 65536) -> None:
    """The soft limit on open files up to the hard one (Linux gives 1,024 soft by default):
    the server's own caps stay far below it, whatever else the process opens."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
        if soft != resource.RLIM_INFINITY and soft < target:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    except (ImportError, ValueError, OSError):
        pass


def _quiet_server_class():
    import uvicorn

    class QuietServer(uvicorn.Server):
        """uvicorn without its signal handling: the runtime owns SIGINT and SIGTERM (uvicorn
        would take them over while it serves, and raise them again when it stops)."""

        def capture_signals(self):
            return contextlib.nullcontext()

    return QuietServer


class ApiServer:
    """The goal API as a runtime service: uvicorn on the runtime's event loop."""

    name = "goal-api"

    def __init__(self, desk: GoalDeskPort, host: str, port: int, token: str | None,
                 stream_rate_hz: float = 5.0, console: ConsolePort | None = None,
                 limits: ConnectionLimits = ConnectionLimits(),
                 tls: tuple[str, str] | None = None) -> None:
        import uvicorn

        if tls is not None:
            check_tls(*tls)

        if not is_loopback(host) and not token:
            raise ApiSetupError(
                f"--api {host}:{port} is reachable from other machines: give a token "
                f"(--api-token-file FILE, or the {TOKEN_ENV} environment variable)")
        self.host, self.port = host, port
        check_listen(host, port)
        from autopilot.console import Console

        self.console = Console(console) if console is not None else None
        self.app = build_app(desk, token if token else None, stream_rate_hz,
                             loopback_only=is_loopback(host), console=self.console)
        _raise_open_files_limit()
        self.protocol = _guarded_protocol(limits)
        config = uvicorn.Config(self.app, host=host, port=port, log_level="warning",
                                lifespan="off", ws="websockets-sansio", access_log=False,
                                http=self.protocol, h11_max_incomplete_event_size=16 * 1024,
                                backlog=limits.backlog,
                                **({"ssl_certfile": tls[0], "ssl_keyfile": tls[1]}
                                   if tls is not None else {}))
        self.scheme = "https" if tls is not None else "http"
        self._server = _quiet_server_class()(config)
        self.started = asyncio.Event()
        self._serve_task: asyncio.Future | None = None

    @property
    def bound_port(self) -> int:
        servers = getattr(self._server, "servers", None) or []
        for server in servers:
            for sock in server.sockets:
                return sock.getsockname()[1]
        return self.port

    async def run(self) -> None:
        serve = self._serve_task = asyncio.ensure_future(self._serve())
        # (uvicorn says it has started with a flag only)
        while not self._server.started and not serve.done():  # noqa: ASYNC110
            await asyncio.sleep(0.01)
        if serve.done():  # it could not start (the port was taken meanwhile, …)
            serve.result()
            raise OSError(f"the goal API could not listen on {self.host}:{self.port}")
        self.started.set()
        log.info("goal API on http://%s:%d/ (docs at /docs)", self.host, self.bound_port)
        await serve

    async def _serve(self) -> None:
        try:
            await self._server.serve()
        except SystemExit:  # uvicorn exits when it cannot start; we are not the process
            raise OSError(f"the goal API could not listen on {self.host}:{self.port}") from None

    async def stop(self, graceful: bool = True, linger_s: float = 1.0) -> None:
        """Stop serving, closing connections — after ``linger_s`` (wall clock) when the run
        ended normally, so that clients following a goal that ended it (a land goal) can read
        how it ended; at once otherwise."""
        if graceful and self.started.is_set() and linger_s > 0:
            await asyncio.sleep(linger_s)
        self._server.should_exit = True
        if self.console is not None:
            self.console.close()
        task = self._serve_task
        if task is not None and not task.done() and not graceful:
            task.cancel()
        elif task is not None and not task.done():
            try:
                await asyncio.wait_for(asyncio.shield(task), 5.0)
            except (TimeoutError, Exception):  # (it is going away either way)
                task.cancel()


def read_token(path: str | None) -> str | None:
    """The API token from a file (first line), else from the environment; None: none."""
    import os
    from pathlib import Path

    if path:
        try:
            text = Path(path).read_text().strip()
        except OSError as exc:
            raise ApiSetupError(f"--api-token-file {path}: {exc.strerror or exc}") from None
        token = text.splitlines()[0].strip() if text else ""
        if len(token) < 16:
            raise ApiSetupError(f"--api-token-file {path}: the token (its first line) is too "
                                "short (at least 16 characters)")
        return token
    value = os.environ.get(TOKEN_ENV, "").strip()
    if value and len(value) < 16:
        raise ApiSetupError(f"{TOKEN_ENV}: the token is too short (at least 16 characters)")
    return value or None
