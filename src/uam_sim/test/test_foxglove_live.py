"""The Foxglove live view speaks the Foxglove WebSocket protocol: a client sees our channels,
subscribes, and receives the network on subscribing and the fleet as it is logged.

The client is hand-written on a plain socket (RFC 6455 framing, a few lines), so that the test
needs no WebSocket library beyond the server under test.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time

import numpy as np
import pytest

pytest.importorskip("foxglove")

from uam_sim.views.foxglove_live import (TOPIC_FLEET, TOPIC_FLEET_GEO, TOPIC_METRICS,  # noqa: E402
                                   TOPIC_NETWORK, TOPIC_ROUTES, FoxgloveLive)
from uam_sim.views.std_msgs_export import scenario_start_ns  # noqa: E402

START = "2025-01-06T00:00:00Z"


class WsClient:
    def __init__(self, port: int):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           "Sec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        self.handshake = head.decode()

    def _read(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise ConnectionError("server closed the connection")
            out += chunk
        return out

    def frame(self) -> tuple[int, bytes]:
        b0, b1 = self._read(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._read(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._read(8))[0]
        return b0 & 0x0F, self._read(n)

    def send_text(self, text: str) -> None:
        data = text.encode()
        mask = os.urandom(4)
        head = bytes([0x81]) + (bytes([0x80 | len(data)]) if len(data) < 126
                                else bytes([0x80 | 126]) + struct.pack(">H", len(data)))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def until(self, pred, timeout_s: float = 10.0):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            op, payload = self.frame()
            got = pred(op, payload)
            if got is not None:
                return got
        raise AssertionError("expected frame did not arrive")


def test_a_client_sees_the_channels_gets_the_network_and_the_fleet():
    from uam_planner.network import load_network
    from view_runs import TINY

    net = load_network(TINY)
    start_ns = scenario_start_ns(START)
    with FoxgloveLive(net, port=0, scenario_start_utc=START) as live:
        client = WsClient(live.port)
        assert " 101 " in client.handshake.splitlines()[0]

        def advertise(op, payload):
            if op == 1:
                msg = json.loads(payload)
                if msg.get("op") == "advertise":
                    return {c["topic"]: c for c in msg["channels"]}
        channels = client.until(advertise)
        assert {TOPIC_NETWORK, TOPIC_ROUTES, TOPIC_FLEET, TOPIC_FLEET_GEO, TOPIC_METRICS} <= set(channels)
        assert channels[TOPIC_FLEET]["schemaName"] == "foxglove.PointCloud"
        assert channels[TOPIC_FLEET_GEO]["schemaName"] == "foxglove.LocationFixes"
        client.send_text(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channels[TOPIC_NETWORK]["id"]},
            {"id": 2, "channelId": channels[TOPIC_FLEET]["id"]}]}))

        def data(sub_id):
            def pred(op, payload):
                if op == 2 and payload[0] == 1:   # binary messageData
                    sid, log_ns = struct.unpack_from("<IQ", payload, 1)
                    if sid == sub_id:
                        return log_ns, payload[13:]
            return pred
        # subscribing to the network channel sends the network scene at once
        log_ns, scene = client.until(data(1))
        assert log_ns == start_ns
        assert b"Aerodrome A" in scene and b"Aerodrome C" in scene
        # the fleet, as logged: real-UTC log time, the positions as float32 x, y, z
        pos = np.array([[10.0, 20.0, 120.0], [-500.0, 300.0, 120.0]])
        deadline = time.monotonic() + 5
        got = None
        while got is None and time.monotonic() < deadline:   # subscription is asynchronous
            live.on_fleet(7 * 1_000_000_000, ["r1", "r2"], pos)
            try:
                client.sock.settimeout(0.5)
                got = client.until(data(2), timeout_s=0.5)
            except (AssertionError, socket.timeout):
                pass
        client.sock.settimeout(10)
        assert got is not None, "no fleet message reached the subscriber"
        log_ns, cloud = got
        assert log_ns == start_ns + 7 * 1_000_000_000
        assert pos.astype("<f4").tobytes() in cloud
        client.sock.close()


def test_bad_port_and_start_are_refused():
    with pytest.raises(ValueError, match="port: 70000"):
        FoxgloveLive(None, port=70000)
    with pytest.raises(ValueError, match="scenario_start_utc"):
        FoxgloveLive(None, port=0, scenario_start_utc="noon")
