"""The view's web server: a local page over HTTP, pushed to over a WebSocket.

:class:`ViewServer` runs an aiohttp application on an event loop in a
thread of its own, so that the program that feeds it never waits for it:
other threads hand it work with :meth:`ViewServer.post` (or a feed's
changes with :meth:`ViewServer.send`), which only schedule it on the loop.
``apygis view`` and ``orient map --view`` serve this way; a session's view
runs it in a process of its own (:mod:`apygis.view.process`), so that
serving pages takes no time from the compilation.

Addresses (every one under the secret token, so that another user of the
machine, who cannot read the URL printed to this terminal, gets ``403``)::

    http://127.0.0.1:PORT/TOKEN/             the page (index.html, app.js, style.css)
    http://127.0.0.1:PORT/TOKEN/state.json   the whole state (what a page gets first)
    ws://127.0.0.1:PORT/TOKEN/ws             the push channel (state, then deltas)

The page can only view: the server has no address that changes anything, it
answers only GET (and HEAD), and what a page sends on its WebSocket is read
and dropped. It binds to 127.0.0.1 unless told otherwise; a WebSocket whose
``Origin`` is not the page's own is refused. Nothing on the page comes from
elsewhere (the page's Content-Security-Policy allows only its own origin).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import logging
import secrets
import socket
import threading
from collections.abc import Callable
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

from apygis.errors import ViewError
from apygis.view.feed import deliver
from apygis.view.hub import Viewer, ViewHub

__all__ = ["ViewServer", "bind_socket", "is_loopback", "page_url"]

log = logging.getLogger(__name__)

_STATIC = {
    "": ("index.html", "text/html"),
    "app.js": ("app.js", "text/javascript"),
    "style.css": ("style.css", "text/css"),
}
_CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
#: Largest message a page may send (they are read and dropped), bytes.
MAX_INCOMING = 4096


def is_loopback(host: str) -> bool:
    """Whether ``host`` names only this machine (``127.0.0.1``, ``::1``, ``localhost``)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def page_url(host: str, port: int, token: str) -> str:
    """The address of the page served on ``host:port`` under ``token``."""
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{port}/{token}/"


def bind_socket(host: str, port: int) -> socket.socket:
    """A listening, non-blocking socket on ``host:port`` (0: a free port).

    Raises
    ------
    ViewError
        The host is not this machine's, or the port is in use or not allowed.
    """
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ViewError(f"view: cannot serve on host {host!r}: {exc.strerror}") from None
    family, _, _, _, addr = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(addr)
        sock.listen(16)
    except OSError as exc:
        sock.close()
        raise ViewError(f"view: cannot serve on {host}:{port}: {exc.strerror or exc}") from None
    sock.setblocking(False)
    return sock


def _static_files() -> dict[str, tuple[bytes, str]]:
    pkg = resources.files("apygis.view") / "static"
    return {key: ((pkg / name).read_bytes(), ctype) for key, (name, ctype) in _STATIC.items()}


class ViewServer:
    """Serve ``hub``'s page on ``host:port`` from a thread of its own.

    Parameters
    ----------
    hub : ViewHub
        The state and the viewers (used on the server's loop only).
    host : str
        Address to bind (default 127.0.0.1: this machine only).
    port : int
        Port; 0 takes a free one (the URL says which).
    token : str, optional
        The secret in every address; default a random one (128 bits).
    sock : socket.socket, optional
        A socket already bound and listening (:func:`bind_socket`), served
        instead of binding ``host:port``.
    """

    def __init__(
        self,
        hub: ViewHub | None,
        host: str = "127.0.0.1",
        port: int = 0,
        token=None,
        sock: socket.socket | None = None,
    ):
        self.hub: ViewHub = hub  # type: ignore[assignment]  # set before start() where None
        self.host = host
        self.port = sock.getsockname()[1] if sock is not None else port
        self.token = token or secrets.token_urlsafe(16)
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stopped = threading.Event()
        self._error: BaseException | None = None
        self._runner: Any = None
        self._sockets: set[Any] = set()
        self._sock: socket.socket | None = sock
        self._connected = threading.Event()
        self._closed = False

    # ------------------------------------------------------------------ life

    @property
    def url(self) -> str:
        """The page's address, token included."""
        return page_url(self.host, self.port, self.token)

    @property
    def closed(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._closed

    def bind(self) -> None:
        """Take the address now (a command checks it before it writes anything).

        Raises
        ------
        ViewError
            The host is not this machine's, or the port is in use or not allowed.
        """
        if self._sock is None:
            self._sock = bind_socket(self.host, self.port)
            self.port = self._sock.getsockname()[1]

    def start(self, timeout: float = 30.0) -> str:
        """Bind, start the thread, and return the URL once the page can be loaded.

        Raises
        ------
        ViewError
            The address cannot be bound (in use, not this machine's) or the
            server did not start.
        """
        try:
            import aiohttp  # noqa: F401
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise ViewError(f"view: the web server package is missing ({exc})") from None
        if self.hub is None:
            raise ViewError("view: nothing to show (no hub)")
        self.bind()
        sock = self._sock
        files = _static_files()
        self._thread = threading.Thread(
            target=self._main, args=(sock, files), name="apygis-view", daemon=True
        )
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            raise ViewError(f"view: the server did not start: {self._error or 'timed out'}")
        return self.url

    def _main(self, sock: socket.socket, files) -> None:
        loop = asyncio.new_event_loop()
        self.loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve(sock, files))
        except BaseException as exc:  # reported to start()
            self._error = exc
            self._ready.set()
        else:
            self._ready.set()
            loop.run_forever()
        finally:
            with contextlib.suppress(Exception):
                loop.run_until_complete(self._shutdown())
            loop.close()
            self._stopped.set()

    async def _serve(self, sock: socket.socket, files) -> None:
        from aiohttp import web

        token = self.token
        prefix = f"/{token}/"
        bprefix = prefix.encode()

        @web.middleware
        async def guard(request, handler):
            path = request.raw_path.split("?", 1)[0].encode("utf-8", "surrogateescape")
            if not (
                hmac.compare_digest(path[: len(bprefix)], bprefix)
                or hmac.compare_digest(path, bprefix[:-1])
            ):
                return web.Response(
                    status=403, text="403: this page needs the address printed by apygis\n"
                )
            if request.method not in ("GET", "HEAD"):
                return web.Response(status=405, text="405: the view can only be looked at\n")
            return await handler(request)

        def page(key: str):
            body, ctype = files[key]

            async def handler(request):
                return web.Response(
                    body=body,
                    content_type=ctype,
                    charset="utf-8",
                    headers={
                        "Cache-Control": "no-store",
                        "Content-Security-Policy": _CSP,
                        "Referrer-Policy": "no-referrer",
                        "X-Content-Type-Options": "nosniff",
                    },
                )

            return handler

        async def to_slash(request):
            raise web.HTTPFound(prefix)

        async def state(request):
            _, text = self.hub.state_json()
            return web.Response(
                text=text, content_type="application/json", headers={"Cache-Control": "no-store"}
            )

        async def ws_handler(request):
            origin = request.headers.get("Origin")
            if origin is not None and urlsplit(origin).netloc != request.host:
                return web.Response(status=403, text="403: not this page's origin\n")
            ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=MAX_INCOMING)
            await ws.prepare(request)
            viewer = Viewer(ws.send_str, self.hub.queue_limit)
            self.hub.add(viewer)
            self._sockets.add(ws)
            self._connected.set()
            sender = asyncio.ensure_future(viewer.run(self.hub))
            sender.add_done_callback(lambda t: t.cancelled() or asyncio.ensure_future(ws.close()))
            try:
                async for _ in ws:  # view only: whatever a page sends is dropped
                    pass
            finally:
                self.hub.remove(viewer)
                self._sockets.discard(ws)
                sender.cancel()
                with contextlib.suppress(BaseException):
                    await sender
            return ws

        app = web.Application(middlewares=[guard], client_max_size=MAX_INCOMING)
        app.router.add_get(prefix[:-1], to_slash)
        app.router.add_get(prefix, page(""))
        app.router.add_get(prefix + "app.js", page("app.js"))
        app.router.add_get(prefix + "style.css", page("style.css"))
        app.router.add_get(prefix + "state.json", state)
        app.router.add_get(prefix + "ws", ws_handler)
        runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=1.0)
        await runner.setup()
        self._runner = runner
        site = web.SockSite(runner, sock)
        await site.start()

    async def _shutdown(self) -> None:
        for ws in list(self._sockets):
            with contextlib.suppress(Exception):
                await asyncio.wait_for(ws.close(code=1001, message=b"server stopped"), 1.0)
        if self._runner is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._runner.cleanup(), 3.0)

    def stop(self, timeout: float = 5.0) -> None:
        """Close the pages and stop the server (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._thread is None and self._sock is not None:  # bound, never started
            self._sock.close()
        loop = self.loop
        if loop is not None and self._thread is not None and self._thread.is_alive():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(loop.stop)
            self._stopped.wait(timeout)

    # ------------------------------------------------------------------ feeding

    def post(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` on the server's loop, soon; from any thread, never waiting.

        After :meth:`stop` (or if the server failed) it does nothing.
        """
        loop = self.loop
        if self._closed or loop is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(self._run_safely, fn, args)

    def _run_safely(self, fn, args) -> None:
        try:
            fn(*args)
        except Exception:
            log.exception("view: a change could not be applied")

    def send(self, changes: list[dict], status: dict | None, display: dict | None) -> bool:
        """Hand a feed's changes and latest status line to the hub, without waiting.

        The in-process counterpart of :meth:`apygis.view.process.ViewProcess.send`
        (see :func:`apygis.view.feed.deliver`). False once the server is stopped.
        """
        if self._closed or self.loop is None:
            return False
        self.post(deliver, self.hub, changes, status, display)
        return True

    def wait_for_viewer(self, timeout: float) -> bool:
        """Wait until a page has connected (True), or ``timeout`` seconds (False)."""
        return self._connected.wait(timeout)

    def stats(self) -> dict[str, int]:
        """:meth:`ViewHub.stats`, read from the loop (a copy; may lag by a moment)."""
        return dict(self.hub.stats())
