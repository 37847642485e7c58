"""The goal API: a local HTTP + WebSocket server for a companion computer's programs (seed 004's
action servers), on FastAPI, served by uvicorn inside the autopilot's own event loop.

======================================  =====================================================
``GET /api/status``                     status code and name, step, goal, position, velocity,
                                        yaw, armed, mode, battery
``WS /api/status/stream``               the same, pushed 5 times a second
``POST /api/goals``                     one step as in a mission file, e.g. ``{"orbit": {…}}``
                                        → 202 ``{"goal_id"}``; 409 (busy, with the reason);
                                        422 naming the bad key
``GET /api/goals``                      every goal so far
``GET /api/goals/{id}``                 its state, feedback (phase, progress, photos), result
``POST /api/goals/{id}/cancel``         → the vehicle hovers (status 3)
``POST /api/abort``                     → status 12 and the safe stop (hold, land, disarm)
``GET /docs``                           the OpenAPI page (served from the package, no CDN):
                                        every goal kind and its parameters
``GET /``, ``GET /video/{camera}.mjpg``  with ``--console``: the operator console's page, its
``WS /api/console``                     live video, and its socket (values, events, keys);
``GET /api/console/stats``              see :mod:`autopilot.console`
======================================  =====================================================

The server itself (uvicorn, the connection limits, TLS, the token file) is
:mod:`autopilot.api_server`'s.

Security: it binds 127.0.0.1 unless told otherwise; on any other address every request needs
``Authorization: Bearer TOKEN`` (the token from a file or ``AUTOPILOT_API_TOKEN``; without one
the server refuses to start). On loopback, requests must be addressed to a loopback name (a web
page elsewhere whose name resolves to 127.0.0.1 — DNS rebinding — is refused). Requests that
change anything carry JSON or no body, and no foreign ``Origin`` (a web page elsewhere cannot
drive the vehicle), and no browser fetch made for another origin's page (``Sec-Fetch-Site``);
no CORS headers are ever sent. The console's page cannot send a header from the browser's
address bar: off loopback, ``/?token=TOKEN`` once sets the token as an HttpOnly, SameSite=Strict
cookie, which the page's video, socket and goal requests then carry. Handlers only read the
runtime's state and queue requests (a goal's validation, which may read a file, runs in a
thread): they never wait on the vehicle, so the control loop is never held up by a client.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
from typing import TYPE_CHECKING, Any

from fastapi import FastAPI, Request, WebSocket
from fastapi.openapi.utils import get_openapi
from fastapi.responses import HTMLResponse, JSONResponse, Response
from pydantic import ConfigDict, TypeAdapter, create_model

from autopilot.goals import GoalError, goal_kinds, validate_goal
from autopilot.steps import STEP_KINDS

if TYPE_CHECKING:
    from autopilot.console import Console
    from autopilot.runtime.ports import GoalDeskPort

log = logging.getLogger(__name__)

TOKEN_ENV = "AUTOPILOT_API_TOKEN"


class ApiSetupError(ValueError):
    """The API cannot be served as asked (an address without a token, a bad address)."""


def _goal_example() -> dict:
    """A goal for the API's documentation: the first goal kind with example parameters."""
    kinds = goal_kinds()
    return next(({name: dict(STEP_KINDS[name].example)} for name in kinds
                 if STEP_KINDS[name].example is not None), {kinds[0]: {}} if kinds else {})


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (or ``:PORT``, or ``PORT``: on 127.0.0.1)."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = "", text
    host = host.strip("[]") or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        raise ApiSetupError(f"--api {text!r}: expected HOST:PORT, e.g. 127.0.0.1:8080") from None
    if not 0 <= number <= 65535:
        raise ApiSetupError(f"--api {text!r}: port {number} is out of range")
    return host, number


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_listen(host: str, port: int) -> None:
    """Can the API listen there? (Asked before anything flies.)"""
    import socket

    if not port:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            raise ApiSetupError(f"--api {host}:{port}: cannot listen there "
                                f"({exc.strerror or exc})") from None


def goal_schema() -> dict:
    """JSON Schema of a goal: one of the step kinds, each ``{KIND: {its parameters}}``."""
    members = [create_model(f"{name.title().replace('_', '')}Goal",
                            __config__=ConfigDict(extra="forbid", allow_inf_nan=False),
                            **{name: (STEP_KINDS[name].params, ...)})
               for name in goal_kinds()]
    from typing import Union

    return TypeAdapter(Union[tuple(members)]).json_schema(  # noqa: UP007
        ref_template="#/components/schemas/{model}")


#: the largest goal body taken (the largest survey polygon a goal may carry fits many times)
MAX_GOAL_BODY_B = 64 * 1024
#: how deeply a goal's JSON may nest (a goal needs four levels: polygon holes)
MAX_GOAL_DEPTH = 16


def _depth(value: Any, limit: int = MAX_GOAL_DEPTH + 1) -> int:
    """How deeply ``value`` nests (lists and objects), counted no further than ``limit``."""
    deepest, level, todo = 0, 0, [(value, 1)]
    while todo:
        item, level = todo.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, level)
            if level >= limit:
                return level
            todo.extend((child, level + 1)
                        for child in (item.values() if isinstance(item, dict) else item))
    return deepest


#: the slowest live video a viewer may ask for (slower: a viewer that receives nothing while
#: the encoder runs for it)
MIN_VIDEO_FPS = 0.2

def _hardened(response):
    """Every answer: its type as declared (no sniffing), and no address leaked onwards."""
    response.headers.setdefault("X-Content-Type-Options", "nosniff")
    response.headers.setdefault("Referrer-Policy", "no-referrer")
    return response


_LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "::1"})


def _hostname(host_port: str) -> str:
    """The name in ``HOST[:PORT]`` (``[::1]:8080`` → ``::1``)."""
    host = host_port.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host[1:]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


TOKEN_COOKIE = "autopilot_token"

PAGE_SECURITY = {"Cache-Control": "no-store", "X-Frame-Options": "DENY",
                 "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
                 "style-src 'self' 'unsafe-inline'; script-src 'self' 'unsafe-inline'; "
                 "connect-src 'self'; frame-ancestors 'none'",
                 "Referrer-Policy": "no-referrer"}

#: the console's sign-in page off loopback: the token typed in (it never sits in an address,
#: the browser's history or a server's log), sent once to /api/login, kept as a cookie
SIGN_IN_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>autopilot: sign in</title>
<style>body{font-family:sans-serif;margin:4em auto;max-width:26em}input{width:100%;margin:.5em 0}
</style></head><body><h1>autopilot console</h1>
<form id="f"><label>API token <input id="t" type="password" autocomplete="current-password"
autofocus required></label><button>Sign in</button></form><p id="e"></p>
<script>
document.getElementById("f").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const r = await fetch("/api/login", {method: "POST", credentials: "same-origin",
    headers: {"Content-Type": "application/json"},
    body: JSON.stringify({token: document.getElementById("t").value})});
  if (r.ok) { location.replace("/"); }
  else { document.getElementById("e").textContent = "wrong token"; }
});
</script></body></html>"""


def cookie_name(headers) -> str:
    """The token's cookie, one per port: browsers share cookies across a host's ports, and
    a run's console and a simulator's on one machine each keep their own."""
    host = headers.get("host", "")
    port = host.rsplit(":", 1)[1] if host.count(":") == 1 or "]:" in host else "80"
    return f"{TOKEN_COOKIE}_{port if port.isdigit() else '80'}"


def build_app(desk: GoalDeskPort, token: str | None, stream_rate_hz: float = 5.0,
              loopback_only: bool = True, console: Console | None = None) -> FastAPI:
    app = FastAPI(title="autopilot goal API", version="1", docs_url=None, redoc_url=None,
                  description="Goals (mission steps) at runtime, status, cancel and abort. "
                  "Local by default; any other address needs a bearer token."
                  + (" The operator console: the page at /, live video at "
                     "/video/{camera}.mjpg, values, events and keys on the WebSocket "
                     "/api/console (see autopilot.console)." if console is not None else ""))

    def refuse(status: int, error: str) -> JSONResponse:
        return _hardened(JSONResponse({"error": error}, status_code=status))

    def token_is(given: str | None) -> bool:
        return token is not None and given is not None and \
            hmac.compare_digest(given.encode(), token.encode())

    def authorised(headers, cookies=None) -> bool:
        """The bearer token in the header, or (the console's page, which a browser loads
        without headers of its own) in the same-site cookie ``/?token=`` set."""
        if token is None:
            return True
        given = headers.get("authorization", "")
        if hmac.compare_digest(given.encode(), f"Bearer {token}".encode()):
            return True
        return token_is((cookies or {}).get(cookie_name(headers)))

    def host_ok(headers) -> bool:
        """On loopback, only requests addressed to a loopback name (a page on another site
        whose name resolves to 127.0.0.1 — DNS rebinding — carries its own name)."""
        if not loopback_only:
            return True
        name = _hostname(headers.get("host", ""))
        # a loopback address written out (127.0.0.2, …) is no name a page could rebind
        return name in _LOOPBACK_NAMES or (name != "localhost" and is_loopback(name))

    def origin_ok(headers) -> bool:
        """No foreign page: a browser's request carries its page's origin, which must be
        this server exactly (scheme aside) — not another port on the same host (a notebook,
        a dev server), nor another name — and no ``Sec-Fetch-Site`` but same-origin/none."""
        if headers.get("sec-fetch-site") in ("cross-site", "same-site"):
            return False
        origin = headers.get("origin")
        if origin is None:
            return True  # not a browser's cross-site request
        return origin.split("://", 1)[-1].lower() == headers.get("host", "").lower()

    @app.middleware("http")
    async def guard(request: Request, call_next):
        if not host_ok(request.headers):
            return refuse(403, "requests must be addressed to 127.0.0.1 or localhost")
        if request.headers.get("sec-fetch-site") in ("cross-site", "same-site"):
            # a browser fetching for a page of another origin (an <img> of the video, …)
            return refuse(403, "cross-origin request refused")
        if not authorised(request.headers, request.cookies):
            path = request.url.path
            if console is not None and path == "/" and request.method in ("GET", "HEAD") \
                    and request.query_params.get("token") is None:
                # the console's sign-in page: the token typed in, never in an address
                return _hardened(HTMLResponse(SIGN_IN_PAGE, status_code=401,
                                              headers=PAGE_SECURITY))
            if not (console is not None and (
                    (path == "/api/login" and request.method == "POST")
                    or (path == "/" and token_is(request.query_params.get("token"))))):
                return refuse(401, "a bearer token is needed (Authorization: Bearer TOKEN; "
                              "the console: open / and sign in)")
        if request.method not in ("GET", "HEAD", "OPTIONS"):
            if not origin_ok(request.headers):
                return refuse(403, f"cross-origin request from {request.headers['origin']} "
                              "refused")
            kind = request.headers.get("content-type", "").split(";")[0].strip()
            if request.url.path == "/api/goals" and kind != "application/json":
                return refuse(415, "send the goal as application/json")
            if kind and kind != "application/json":  # (a form posted by a web page)
                return refuse(415, f"{kind} is not taken here: send application/json or "
                              "no body")
        return _hardened(await call_next(request))

    @app.get("/api/status", summary="The mission status and the vehicle's state")
    async def status() -> dict:
        return desk.api_status()

    async def socket_allowed(ws: WebSocket) -> bool:
        if not host_ok(ws.headers) or not origin_ok(ws.headers):
            await ws.close(code=4403)
            return False
        if not authorised(ws.headers, ws.cookies):
            await ws.close(code=4401)
            return False
        await ws.accept()
        return True

    @app.websocket("/api/status/stream")
    async def stream(ws: WebSocket) -> None:
        if not await socket_allowed(ws):
            return
        period = 1.0 / stream_rate_hz
        try:
            while True:
                await ws.send_text(json.dumps(desk.api_status()))
                await asyncio.sleep(period)  # (wall clock: it is for people and programs)
        except Exception:  # the client went away, or the server is closing
            return

    @app.post("/api/goals", status_code=202, summary="Start a goal: one mission step",
              openapi_extra={"requestBody": {"required": True, "content": {
                  "application/json": {"schema": {"$ref": "#/components/schemas/Goal"},
                                       "example": _goal_example()}}}},
              responses={409: {"description": "another goal runs, or the mission is busy"},
                         422: {"description": "invalid goal: the bad key is named"}})
    async def submit(request: Request):
        raw = bytearray()
        async for chunk in request.stream():  # read no further than the limit
            raw += chunk
            if len(raw) > MAX_GOAL_BODY_B:
                return JSONResponse({"error": f"a goal's body is at most {MAX_GOAL_BODY_B} "
                                              "bytes"}, status_code=413)
        try:
            body: Any = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
            why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
            return JSONResponse({"error": f"the body is not JSON: {why}"}, status_code=422)
        if _depth(body) > MAX_GOAL_DEPTH:
            return JSONResponse({"error": f"a goal nests at most {MAX_GOAL_DEPTH} levels"},
                                status_code=422)
        try:
            # (validation may read files, e.g. a hover_image goal's image: off the loop)
            step = await asyncio.to_thread(validate_goal, body, desk.config,
                                           desk.goal_site())
            goal = desk.submit_goal(step)
        except GoalError as exc:
            return JSONResponse(exc.as_dict(), status_code=exc.status)
        # what may not go as the sender expects, though it flies (e.g. an orbit whose centre
        # its photos will not show)
        warnings = list(STEP_KINDS[step.name].warnings(step.params, desk.config))
        return {"goal_id": goal.id, "state": goal.state, "warnings": warnings}

    @app.get("/api/goals", summary="Every goal so far")
    async def goals() -> list[dict]:
        return [g.as_dict() for g in (desk.goals.goals.values() if desk.goals else [])]

    def goal_answer(action, goal_id: str):
        if desk.goals is None:
            return JSONResponse({"error": "this run takes no goals"}, status_code=404)
        try:
            return action(goal_id).as_dict()
        except GoalError as exc:
            return JSONResponse(exc.as_dict(), status_code=exc.status)

    @app.get("/api/goals/{goal_id}", summary="A goal's state, feedback and result")
    async def goal(goal_id: str):
        return goal_answer(desk.goals.get if desk.goals else None, goal_id)

    @app.post("/api/goals/{goal_id}/cancel", summary="Cancel a goal: the vehicle hovers")
    async def cancel(goal_id: str):
        return goal_answer(desk.goals.cancel if desk.goals else None, goal_id)

    @app.post("/api/abort", summary="Abort: hold, land, disarm (status 12)")
    async def abort() -> dict:
        desk.abort("abort requested through the goal API")
        return {"status": "aborting"}

    if console is not None:
        _console_routes(app, console, socket_allowed, token_is)

    def openapi() -> dict:
        if app.openapi_schema is None:
            schema = get_openapi(title=app.title, version=app.version,
                                 description=app.description, routes=app.routes)
            goal = goal_schema()
            components = schema.setdefault("components", {}).setdefault("schemas", {})
            components.update(goal.pop("$defs", {}))
            components["Goal"] = goal
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi
    _docs_routes(app)
    return app


# The OpenAPI page, served from the installed swagger-ui-bundle (FastAPI's default loads its
# scripts from a CDN: unpinned code in the origin that can fly the vehicle, and no page at all
# offline on a companion computer). Its own script starts it, so the policy allows no inline
# script.
_DOCS_PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>autopilot goal API</title>
<link rel="stylesheet" href="/docs/static/swagger-ui.css"></head>
<body><div id="swagger-ui"></div>
<script src="/docs/static/swagger-ui-bundle.js"></script>
<script src="/docs/start.js"></script></body></html>
"""
_DOCS_START = """SwaggerUIBundle({url: "/openapi.json", dom_id: "#swagger-ui",
  deepLinking: true, presets: [SwaggerUIBundle.presets.apis]});
"""
DOCS_POLICY = ("default-src 'none'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
               "img-src 'self' data:; connect-src 'self'; frame-ancestors 'none'; "
               "base-uri 'none'; form-action 'none'")


def _docs_routes(app: FastAPI) -> None:
    from fastapi.responses import HTMLResponse, Response
    from fastapi.staticfiles import StaticFiles
    from swagger_ui_bundle import swagger_ui_path

    headers = {"Content-Security-Policy": DOCS_POLICY, "Cache-Control": "no-store"}

    @app.get("/docs", include_in_schema=False)
    async def docs_page() -> HTMLResponse:
        return HTMLResponse(_DOCS_PAGE, headers=headers)

    @app.get("/docs/start.js", include_in_schema=False)
    async def docs_start() -> Response:
        return Response(_DOCS_START, media_type="text/javascript", headers=headers)

    app.mount("/docs/static", StaticFiles(directory=str(swagger_ui_path)), name="docs-static")


def _console_routes(app: FastAPI, console: Console, socket_allowed,
                    token_is) -> None:
    from fastapi.responses import RedirectResponse, StreamingResponse

    from autopilot.console import BOUNDARY, page_html

    page = page_html()
    security = PAGE_SECURITY

    def token_cookie(answer, request: Request, given: str) -> None:
        # one per port (a host's other ports are other servers), HttpOnly (no script reads
        # it), SameSite=Strict (no other site's page sends it), Secure over HTTPS (--api-tls-*)
        answer.set_cookie(cookie_name(request.headers), given, httponly=True,
                          samesite="strict", secure=request.url.scheme == "https")

    @app.post("/api/login", summary="The console's sign-in: the token as a cookie",
              status_code=204, include_in_schema=False)
    async def login(request: Request):
        try:
            given = (await request.json()).get("token")
        except (ValueError, AttributeError):
            given = None
        if not isinstance(given, str) or not token_is(given):
            return _hardened(JSONResponse({"error": "wrong token"}, status_code=401))
        answer = Response(status_code=204)
        token_cookie(answer, request, given)
        return answer

    @app.get("/", summary="The operator console (a page: video, values, map, keys, goals)",
             response_class=HTMLResponse)
    async def console_page(request: Request):
        given = request.query_params.get("token")
        if given is not None and token_is(given):
            # once: the token becomes a same-site cookie (the page, its video and its socket
            # then carry it), and leaves the address bar
            answer = RedirectResponse("/", status_code=303)
            token_cookie(answer, request, given)
            return answer
        return HTMLResponse(page, headers=security)

    @app.get("/video/{camera}.mjpg", summary="Live MJPEG of a camera with the overlays",
             response_class=StreamingResponse,
             responses={200: {"content": {f"multipart/x-mixed-replace; boundary={BOUNDARY}":
                                          {}}},
                        404: {"description": "no such camera"}})
    async def video(camera: str, fps: float | None = None, overlay: int = 1):
        if camera not in console.host.vehicle.cameras:
            return JSONResponse({"error": f"no camera {camera!r}; cameras: "
                                 f"{sorted(console.host.vehicle.cameras)}"}, status_code=404)
        if fps is not None and not MIN_VIDEO_FPS <= fps <= 60:  # (NaN fails this too)
            return JSONResponse({"error": f"fps: expected {MIN_VIDEO_FPS:g} <= fps <= 60"},
                                status_code=422)
        feed = console.feed(camera, overlay=bool(overlay))
        return StreamingResponse(feed.stream(fps),
                                 media_type=f"multipart/x-mixed-replace; boundary={BOUNDARY}",
                                 headers={"Cache-Control": "no-store"})

    @app.get("/api/console/stats", summary="What the console's video costs")
    async def console_stats() -> dict:
        return console.stats()

    @app.websocket("/api/console")
    async def console_socket(ws: WebSocket) -> None:
        if await socket_allowed(ws):
            await console.serve_socket(ws)
