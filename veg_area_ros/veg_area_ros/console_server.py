"""The operator's console's web server (aiohttp, in a thread of its own): the page and its two files, the
state as JSON, each view's newest image as a small JPEG, and the controls, which go to a `Controls` object
(the console node) in worker threads so a slow service call never holds up the page. No ROS here: the server
is tested with a stand-in `Controls`, and the node with the real graph."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable
from importlib import resources
from typing import TYPE_CHECKING, Protocol

from aiohttp import web

from .console_state import CHOICES, Access, ConsoleInputError, ImageFeed, host_allowed, now, roi_from_drag

if TYPE_CHECKING:
    from aiohttp.typedefs import Handler

PAGE_FILES = {"/": ("index.html", "text/html"), "/console.js": ("console.js", "text/javascript"),
              "/console.css": ("console.css", "text/css")}
TOKEN_HEADER = "X-Console-Token"
MAX_REQUEST_BYTES = 64 * 1024
CALIBRATION_ACTIONS = ("fit", "commit", "discard")
RECORD_ACTIONS = ("start", "stop")


class Controls(Protocol):
    """What the page can ask for; each returns (done, what happened or why not) and may block."""

    def set_parameters(self, values: dict) -> tuple[bool, str]: ...

    def calibration(self, action: str) -> tuple[bool, str]: ...

    def record(self, action: str) -> tuple[bool, str]: ...


def page_files() -> dict[str, bytes]:
    """The page's files from the package (no CDN, no build step: these three are all the page loads)."""
    folder = resources.files("veg_area_ros") / "console_page"
    return {route: (folder / name).read_bytes() for route, (name, _) in PAGE_FILES.items()}


class ConsoleServer:
    def __init__(self, feeds: dict[str, ImageFeed], state: Callable[[tuple[int, int] | None], dict],
                 controls: Controls, access: Access, port: int) -> None:
        self.feeds, self.state, self.controls, self.access, self.port = feeds, state, controls, access, port
        self.files = page_files()
        self.requests = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None

    # --- running -------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Bind and serve in a thread; OSError (port taken, no such address) is raised here, at start."""
        started: dict = {}
        ready = threading.Event()

        def serve() -> None:
            loop = asyncio.new_event_loop()
            asyncio.set_event_loop(loop)
            self._loop = loop
            try:
                loop.run_until_complete(self._bind())
            except Exception as exc:  # said to the caller, which is waiting
                started["error"] = exc
                ready.set()
                loop.close()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(self._runner.cleanup())
            loop.close()

        self._thread = threading.Thread(target=serve, name="console-server", daemon=True)
        self._thread.start()
        ready.wait()
        if "error" in started:
            raise started["error"]

    async def _bind(self) -> None:
        app = web.Application(client_max_size=MAX_REQUEST_BYTES, middlewares=[self._guard])
        app.router.add_get("/", self._page)
        app.router.add_get("/console.js", self._page)
        app.router.add_get("/console.css", self._page)
        app.router.add_get("/api/state", self._state)
        app.router.add_get("/api/frame/{view}", self._frame)
        app.router.add_post("/api/parameters", self._parameters)
        app.router.add_post("/api/calibration/{action}", self._calibration)
        app.router.add_post("/api/record/{action}", self._record)
        self._runner = web.AppRunner(app, access_log=None)
        await self._runner.setup()
        await web.TCPSite(self._runner, self.access.host, self.port).start()

    def stop(self) -> None:
        if self._loop is not None and self._thread is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=10)

    # --- requests ------------------------------------------------------------------------------------------
    @web.middleware
    async def _guard(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        self.requests += 1
        if not host_allowed(request.host, self.access):
            return web.json_response({"error": "this console answers only to a loopback host name"}, status=421)
        if request.method == "POST" and not self.access.may_change(request.headers.get(TOKEN_HEADER)):
            return web.json_response({"error": "view only: no valid token. Open the console with the address "
                                      "its node printed at start (it ends in ?token=...)"}, status=403)
        return await handler(request)

    async def _page(self, request: web.Request) -> web.Response:
        body = self.files[request.path]
        if request.path == "/":
            body = body.replace(b"{{TOKEN}}", self.access.page_token(request.host).encode())
        return web.Response(body=body, content_type=PAGE_FILES[request.path][1],
                            headers={"Cache-Control": "no-store"})

    async def _state(self, request: web.Request) -> web.Response:
        try:  # the series the page has already: only the points after it are sent
            shown = (int(request.query["run"]), int(request.query["appended"]))
        except (KeyError, ValueError):
            shown = None
        state = await asyncio.get_running_loop().run_in_executor(None, self.state, shown)
        given = request.headers.get(TOKEN_HEADER)
        state["choices"] = {name: list(values) for name, values in CHOICES.items()}
        state["access"] = {"may_change": self.access.may_change(given), "loopback_only": self.access.loopback_only}
        state["views"] = {name: {"frame_size": feed.frame_size, "shown_size": feed.shown_size}
                          for name, feed in self.feeds.items()}
        return web.json_response(state, dumps=lambda value: json.dumps(value, allow_nan=False, default=str))

    async def _frame(self, request: web.Request) -> web.Response:
        feed = self.feeds.get(request.match_info["view"])
        if feed is None:
            return web.json_response({"error": f"no view {request.match_info['view']!r}: "
                                      f"{', '.join(self.feeds)}"}, status=404)
        jpeg, number = await asyncio.get_running_loop().run_in_executor(None, feed.jpeg, now())
        try:
            shown = int(request.query.get("after", "-1"))
        except ValueError:
            shown = -1
        if jpeg is not None and number <= shown:  # the page has this one: not sent (nor decoded) again
            return web.Response(status=304, headers={"Cache-Control": "no-store", "X-Frame-Number": str(number)})
        if jpeg is None:
            return web.Response(status=204, headers={"Cache-Control": "no-store"})
        return web.Response(body=jpeg, content_type="image/jpeg",
                            headers={"Cache-Control": "no-store", "X-Frame-Number": str(number),
                                     "X-Frame-Size": "x".join(map(str, feed.frame_size or (0, 0)))})

    @staticmethod
    async def _json_body(request: web.Request) -> dict:
        try:
            body = await request.json()
        except (ValueError, UnicodeDecodeError):
            raise ConsoleInputError("the request's body is not JSON") from None
        if not isinstance(body, dict):
            raise ConsoleInputError("the request's body must be a JSON object")
        return body

    async def _answer(self, call: Callable[[], tuple[bool, str]]) -> web.Response:
        try:
            done, message = await asyncio.get_running_loop().run_in_executor(None, call)
        except ConsoleInputError as exc:
            return web.json_response({"done": False, "message": str(exc)}, status=400)
        return web.json_response({"done": done, "message": message}, status=200 if done else 409)

    async def _parameters(self, request: web.Request) -> web.Response:
        try:
            body = await self._json_body(request)
            if "roi_drag" in body:  # a rectangle dragged on the shown image: converted with the view's sizes
                drag = body.pop("roi_drag")
                feed = self.feeds.get(drag.get("view", "area")) if isinstance(drag, dict) else None
                if feed is None or feed.frame_size is None or feed.shown_size is None:
                    raise ConsoleInputError("no image shown yet to draw the ROI on")
                body["roi"] = roi_from_drag(tuple(drag["start"]), tuple(drag["end"]), feed.shown_size,
                                            feed.frame_size)
        except (ConsoleInputError, KeyError, TypeError, ValueError) as exc:
            return web.json_response({"done": False, "message": str(exc)}, status=400)
        return await self._answer(lambda: self.controls.set_parameters(body))

    async def _calibration(self, request: web.Request) -> web.Response:
        action = request.match_info["action"]
        if action not in CALIBRATION_ACTIONS:
            return web.json_response({"done": False, "message": f"no action {action!r}"}, status=404)
        return await self._answer(lambda: self.controls.calibration(action))

    async def _record(self, request: web.Request) -> web.Response:
        action = request.match_info["action"]
        if action not in RECORD_ACTIONS:
            return web.json_response({"done": False, "message": f"no action {action!r}"}, status=404)
        return await self._answer(lambda: self.controls.record(action))
