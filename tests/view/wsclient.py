"""A WebSocket client that reads a view as a page does, on a thread of its own (for tests)."""

from __future__ import annotations

import asyncio
import json
import threading
import time


class Mirror:
    """What a page holds after the messages it got: records, entries, status (as app.js does)."""

    def __init__(self):
        self.layers: dict = {}
        self.seq = -1
        self.entries: list = []
        self.status: dict = {}
        self.display: dict = {}
        self.ended = False
        self.kinds: list[str] = []
        self.overlays: list = []

    def feed(self, m: dict) -> None:
        self.kinds.append(m["t"])
        if m["t"] == "state":
            self.seq = m["seq"]
            self.layers = {
                ext: {t: {r[0]: r for r in rows} for t, rows in tables.items()}
                for ext, tables in m["layers"].items()
            }
            self.entries = list(m["entries"])
            self.status = m["status"]
            self.display = m["display"]
            self.ended = m["ended"]
            self.overlays = list(m["overlays"])
        elif m["t"] == "delta":
            if m["seq"] <= self.seq:
                return
            assert m["seq"] == self.seq + 1, (m["seq"], self.seq)
            self.seq = m["seq"]
            for ext, tables in m.get("upsert", {}).items():
                lay = self.layers.setdefault(ext, {"symbols": {}, "line_points": {}, "texts": {}})
                for t, rows in tables.items():
                    for r in rows:
                        lay[t][r[0]] = r
            for ext, tables in m.get("remove", {}).items():
                for t, nums in tables.items():
                    for n in nums:
                        self.layers[ext][t].pop(n, None)
            for ext in m.get("layer_pens", {}):
                self.layers.setdefault(ext, {"symbols": {}, "line_points": {}, "texts": {}})
            last = self.entries[-1][0] if self.entries else 0
            self.entries += [e for e in m.get("entries", []) if e[0] > last]
            self.overlays += m.get("overlays", [])
            if "display" in m:
                self.display = m["display"]
            self.ended = self.ended or bool(m.get("ended"))
        elif m["t"] == "status":
            self.status = {k: v for k, v in m.items() if k not in ("t", "display")}
            self.display = m["display"]

    def records(self) -> dict:
        return {
            ext: {t: sorted(rows.values()) for t, rows in tables.items()}
            for ext, tables in self.layers.items()
        }


class WsClient:
    """Connect to ``url`` (the page's address) and mirror what arrives, until :meth:`close`.

    ``read=False`` connects and then reads nothing (a page that does not keep up)
    until :meth:`start_reading`.
    """

    def __init__(self, url: str, read: bool = True, origin: str | None = None):
        self.url = url.replace("http://", "ws://") + "ws"
        self.mirror = Mirror()
        self.times: list[tuple[float, dict]] = []
        self._reading = threading.Event()
        if read:
            self._reading.set()
        self._opened = threading.Event()
        self._done = threading.Event()
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.error: BaseException | None = None
        self.status_code: int | None = None
        self._origin = origin
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)
        self._thread.start()
        if not self._opened.wait(10):
            raise AssertionError("the WebSocket did not open")

    async def _main(self):
        import aiohttp

        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        headers = {"Origin": self._origin} if self._origin else None
        try:
            async with (
                aiohttp.ClientSession() as http,
                http.ws_connect(self.url, headers=headers, max_msg_size=0) as ws,
            ):
                self._opened.set()
                while not self._reading.is_set():
                    await asyncio.sleep(0.01)
                    if self._stop.is_set():
                        return
                while not self._stop.is_set():
                    try:
                        msg = await asyncio.wait_for(ws.receive(), 0.05)
                    except TimeoutError:
                        continue
                    if msg.type != aiohttp.WSMsgType.TEXT:
                        break
                    m = json.loads(msg.data)
                    self.times.append((time.monotonic(), m))
                    self.mirror.feed(m)
        except aiohttp.WSServerHandshakeError as exc:
            self.status_code = exc.status
            self.error = exc
        except BaseException as exc:
            self.error = exc
        finally:
            self._opened.set()
            self._done.set()

    def start_reading(self) -> None:
        self._reading.set()

    def wait(self, pred, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not pred(self.mirror):
            if time.monotonic() > deadline:
                raise AssertionError(f"not reached within {timeout} s (seq {self.mirror.seq})")
            time.sleep(0.01)

    def close(self) -> None:
        if self._loop is not None and self._stop is not None and not self._done.is_set():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._done.wait(10)
