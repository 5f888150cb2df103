"""The USS server's bounded pool of workers: idle connections cost no thread (300 idle sockets
were 318 threads with werkzeug's thread per connection), wait in a bounded room and are closed
when silent; a burst larger than the pool is served; a full server answers 503."""

import concurrent.futures as cf
import socket
import threading
import time

import pytest
import requests

from uam_planner.f3548 import IntentContext, VolumeSpec
from uam_sim.f3548.auth import generate_dev_keys, mint_token
from uam_sim.f3548.uss_server import SCOPE_INTENTS, IntentStore, UssServer

ORIGIN = (1.29, 103.85, 0.0)


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    return generate_dev_keys(tmp_path_factory.mktemp("uss-keys"))


def _server(keys, **options):
    store = IntentStore(IntentContext(ORIGIN, VolumeSpec.for_separation(100.0)))
    srv = UssServer(store, port=0, auth_key=str(keys[1]), **options).start()
    srv.token = mint_token(keys[0], "localhost", [SCOPE_INTENTS])
    return srv


def _list(srv):
    return requests.get(srv.url + "/uam_fleet/v1/operational_intents", timeout=10,
                        headers={"Authorization": f"Bearer {srv.token}"})


def _until(condition, timeout_s=10.0):
    end = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < end:
        time.sleep(0.02)
    return condition()


def test_300_idle_connections_do_not_make_300_threads(keys):
    srv = _server(keys, workers=4)
    pool = srv._server
    socks = []
    try:
        assert _list(srv).status_code == 200
        before = threading.active_count()
        socks = [socket.create_connection((srv.host, srv.port), timeout=10) for _ in range(300)]
        # every connection accepted: the room holds max_connections (256), the oldest 44 closed
        assert _until(lambda: pool.waiting + pool.dropped_idle >= 300), (pool.waiting, pool.dropped_idle)
        assert (pool.waiting, pool.dropped_idle) == (256, 44)
        assert threading.active_count() - before <= 4, threading.active_count() - before
        # still serving, by a worker, while the idle sockets are held
        assert _list(srv).status_code == 200
        assert threading.active_count() - before <= 4
        assert socks[0].recv(1) == b""  # an evicted one sees the server close it
    finally:
        for s in socks:
            s.close()
        srv.stop()


def test_a_silent_connection_is_closed_after_the_idle_timeout(keys):
    srv = _server(keys, workers=2, idle_timeout_s=0.3)
    try:
        s = socket.create_connection((srv.host, srv.port), timeout=5)
        assert s.recv(1) == b""  # closed by the server, well within the 5 s timeout
        s.close()
        assert srv._server.dropped_idle == 1
    finally:
        srv.stop()


def test_a_burst_larger_than_the_pool_is_served(keys):
    srv = _server(keys, workers=2)
    try:
        with cf.ThreadPoolExecutor(16) as ex:
            codes = list(ex.map(lambda _: _list(srv).status_code, range(64)))
        assert codes == [200] * 64
    finally:
        srv.stop()


def test_a_full_server_answers_503_and_a_stalled_request_frees_its_worker(keys):
    srv = _server(keys, workers=1, max_connections=1, request_timeout_s=1.0)
    try:
        stalled = socket.create_connection((srv.host, srv.port), timeout=5)
        stalled.sendall(b"GET /uam_fleet/v1/operational_intents HTTP/1.1\r\n")  # and no more
        assert _until(lambda: srv._server._busy == 1, 5.0)
        r = _list(srv)
        assert r.status_code == 503 and "1 connections in service" in r.json()["message"]
        assert _until(lambda: srv._server._busy == 0, 5.0)  # the worker gave up on it after 1 s
        assert _list(srv).status_code == 200
        stalled.close()
    finally:
        srv.stop()


def test_pool_settings_are_checked(keys):
    store = IntentStore(IntentContext(ORIGIN, VolumeSpec.for_separation(100.0)))
    with pytest.raises(ValueError, match="workers: 0 is not"):
        UssServer(store, port=0, auth_key=str(keys[1]), workers=0)
    with pytest.raises(ValueError, match="max_connections: 2 is fewer than the 4 workers"):
        UssServer(store, port=0, auth_key=str(keys[1]), workers=4, max_connections=2)
