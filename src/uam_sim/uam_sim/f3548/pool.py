"""A werkzeug WSGI server with a bounded pool of workers (the USS-USS server's HTTP layer).

werkzeug's ``threaded=True`` server starts one thread per accepted connection, with no bound:
300 idle sockets held open by a client were 318 threads. Here one thread accepts connections and
keeps them, costing a file descriptor and no thread, in a *waiting room* (a selector) until their
first bytes arrive; only then does a connection go to one of ``workers`` threads (a
``ThreadPoolExecutor``), which reads the request, answers and closes it (werkzeug answers every
request with ``Connection: close``, so a connection carries one request and never sits idle in a
worker between two). Bounds:

- at most ``max_connections`` connections waiting or in service; at the bound the oldest one still
  waiting for its first byte is closed to make room, and when none is waiting the new connection
  gets a 503 ``ErrorResponse`` and is closed, so the pool's queue never exceeds the bound;
- a connection silent for ``idle_timeout_s`` in the waiting room is closed;
- a worker waits at most ``request_timeout_s`` for each read of the request (a client that stops
  mid-request frees its worker then).

A client that trickles one byte just before every ``request_timeout_s`` still holds a worker; the
pool bounds how many it can hold, not for how long (an asynchronous request parser would).
No third-party server is used: waitress is not among the pinned dependencies, and the pool is a
few lines over werkzeug's own request handling.
"""

from __future__ import annotations

import collections
import json
import selectors
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

from werkzeug.serving import BaseWSGIServer

WORKERS = 8
MAX_CONNECTIONS = 256
IDLE_TIMEOUT_S = 10.0
REQUEST_TIMEOUT_S = 10.0
_LISTEN = object()
_WAKE = object()


class PooledWSGIServer(BaseWSGIServer):
    """``BaseWSGIServer`` whose requests are handled by ``workers`` threads (module docstring).
    ``serve_forever()`` runs the accepting loop in the calling thread; ``shutdown()`` stops it
    from another thread and waits for the workers."""

    multithread = True  # the app runs in several threads (WSGI environ), as with threaded=True

    def __init__(self, host: str, port: int, app, handler=None, workers: int = WORKERS,
                 max_connections: int = MAX_CONNECTIONS, idle_timeout_s: float = IDLE_TIMEOUT_S,
                 request_timeout_s: float = REQUEST_TIMEOUT_S):
        if int(workers) < 1:
            raise ValueError(f"workers: {workers!r} is not a number of threads >= 1")
        if int(max_connections) < int(workers):
            raise ValueError(f"max_connections: {max_connections!r} is fewer than the {workers} workers")
        super().__init__(host, port, app, handler)
        self.workers, self.max_connections = int(workers), int(max_connections)
        self.idle_timeout_s, self.request_timeout_s = float(idle_timeout_s), float(request_timeout_s)
        # shutdown() writes a byte here so that the accepting loop stops at once, not at its next
        # poll (up to 0.5 s later)
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="uss-worker")
        self._waiting: collections.OrderedDict = collections.OrderedDict()  # socket -> (address, since)
        self._busy = 0                    # connections handed to the pool and not yet closed
        self._busy_lock = threading.Lock()
        self._stop = threading.Event()
        self._stopped = threading.Event()
        self._stopped.set()
        self.refused = 0                  # connections answered 503 (every worker busy, none waiting)
        self.dropped_idle = 0             # connections closed in the waiting room (idle or evicted)

    # ---- the accepting loop ----------------------------------------------------------------
    def serve_forever(self, poll_interval: float = 0.5) -> None:
        self._stop.clear()
        self._stopped.clear()
        sel = selectors.DefaultSelector()
        sel.register(self.socket, selectors.EVENT_READ, _LISTEN)
        sel.register(self._wake_r, selectors.EVENT_READ, _WAKE)
        try:
            while not self._stop.is_set():
                for key, _ in sel.select(timeout=min(poll_interval, self.idle_timeout_s)):
                    if key.data is _WAKE:
                        self._drain_wake()
                    elif key.data is _LISTEN:
                        self._accept(sel)
                    else:
                        self._dispatch(sel, key.fileobj)
                self._close_idle(sel, time.monotonic() - self.idle_timeout_s)
        finally:
            for conn in list(self._waiting):
                self._drop(sel, conn)
            sel.close()
            self._stopped.set()

    def shutdown(self) -> None:
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:  # closed, or its buffer already full of wake-ups: the loop wakes anyway
            pass
        self._stopped.wait()
        self._pool.shutdown(wait=True)

    def server_close(self) -> None:
        super().server_close()
        self._wake_r.close()
        self._wake_w.close()

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except OSError:  # nothing more to read (BlockingIOError) or closed
            pass

    def _accept(self, sel) -> None:
        try:
            conn, address = self.socket.accept()
        except OSError:
            return
        if len(self._waiting) + self._busy >= self.max_connections:
            if self._waiting:
                self._drop(sel, next(iter(self._waiting)))  # the oldest still silent
            else:
                self._refuse(conn)
                return
        conn.setblocking(False)
        self._waiting[conn] = (address, time.monotonic())
        sel.register(conn, selectors.EVENT_READ, address)

    def _dispatch(self, sel, conn) -> None:
        sel.unregister(conn)
        address, _ = self._waiting.pop(conn)
        conn.setblocking(True)
        conn.settimeout(self.request_timeout_s)
        with self._busy_lock:
            self._busy += 1
        self._pool.submit(self._serve_one, conn, address)

    def _serve_one(self, conn, address) -> None:
        try:
            self.finish_request(conn, address)
        except Exception:
            self.handle_error(conn, address)
        finally:
            self.shutdown_request(conn)
            with self._busy_lock:
                self._busy -= 1

    def _close_idle(self, sel, before: float) -> None:
        while self._waiting:
            conn, (_, since) = next(iter(self._waiting.items()))
            if since > before:
                break
            self._drop(sel, conn)

    def _drop(self, sel, conn) -> None:
        sel.unregister(conn)
        del self._waiting[conn]
        self.dropped_idle += 1
        conn.close()

    def _refuse(self, conn) -> None:
        self.refused += 1
        body = json.dumps({"message": f"server: {self.max_connections} connections in service, the most "
                                      "it takes; try again"}).encode()
        head = (f"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
                f"Content-Length: {len(body)}\r\nRetry-After: 1\r\nConnection: close\r\n\r\n").encode()
        try:
            conn.setblocking(False)
            conn.send(head + body)  # a fresh socket's send buffer takes it whole; never blocks
        except OSError:
            pass
        finally:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            conn.close()

    @property
    def waiting(self) -> int:
        """Connections accepted and not yet sent to a worker."""
        return len(self._waiting)
